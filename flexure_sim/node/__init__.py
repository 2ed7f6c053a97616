"""The ROS 2 shell around the engine (rclpy); holds no physics."""
