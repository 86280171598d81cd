"""The rclpy nodes: thin layers that convert messages and call the core, sim or records."""
