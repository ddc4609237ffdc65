from services.ros2.service import main

main()
