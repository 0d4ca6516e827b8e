"""mrslam_ros: thin rclpy nodes and tools around mrslam_core."""
