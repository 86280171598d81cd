"""Collaborative dual-SCARA sorting cell on ROS 2 Jazzy, with PyBullet standing in for Gazebo."""
