"""``objscan import``: a fixed-camera RGB-D sequence (an object turned by hand or on a turntable) into a
session folder that ``objscan reconstruct`` registers like an arm's acquisition.

``sources`` reads the frames (a folder of color/depth images, or a RealSense ``.bag``/``.db3`` recording),
``base_frame`` puts a z-up ``base`` on the table plane seen by the camera, ``turns`` estimates or checks
the turn between views with the 4-DoF turn search, and ``session`` writes it all out.
"""
