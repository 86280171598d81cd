"""The maths of the cell, plain numpy and dataclasses: no rclpy import anywhere in here."""
