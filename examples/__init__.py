"""Example programs on roslibpy_lite: ``robot_app`` (the app), ``imu_sim`` (the robot side)."""
