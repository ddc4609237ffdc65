"""ROS 2 without ROS: the cell as standard ROS 2 messages on rmw_zenoh's keys, and sessions as ROS 2 bags.

``rmw`` spells rmw_zenoh's keys, liveliness tokens, QoS and attachments; ``types`` holds the message types
(rosbags' stores for Humble and Jazzy), CDR and RIHS01 hashes; ``convert`` turns objscan's messages into ROS 2
messages and ``topics`` says which goes on which topic; ``service`` is the Zenoh face (``python -m services.ros2``,
``objscan up --ros2``); ``bag`` writes a recorded session as a rosbag2 folder. See docs/ros2.md.
"""
