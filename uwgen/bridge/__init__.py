"""The rclpy side of generated bridge nodes."""
