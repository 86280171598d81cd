"""The rclpy nodes: thin layers that convert messages, call the core and the simulator."""
