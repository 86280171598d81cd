"""A measuring node in the benchmark's process: the fault matrix injects through it."""
import time
from typing import Optional

import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState


class Probe:
    """A node of its own context in this process; ``with Probe() as probe:`` closes it."""

    def __init__(self):
        """Join the graph with a node that keeps the newest ``joint_states``."""
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('fault_probe', context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.state: Optional[JointState] = None
        # depth 1: the newest state, never a backlog (a slow probe would lag the graph)
        self.node.create_subscription(JointState, 'joint_states', self._on_state, 1)

    def _on_state(self, msg) -> None:
        self.state = msg

    def spin(self, seconds: float) -> None:
        """Spin the probe node for ``seconds`` of wall time."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def wait_state(self, timeout: float = 15.0) -> JointState:
        """Return the newest ``joint_states`` once one has come (discovery takes a while)."""
        end = time.monotonic() + timeout
        while self.state is None and time.monotonic() < end:
            self.spin(0.05)
        if self.state is None:
            raise RuntimeError('no joint_states heard from the launched graph')
        return self.state

    def publisher(self, msg_type, topic: str, readers: int = 1, timeout: float = 10.0):
        """Return a publisher on ``topic`` once ``readers`` of the graph match it (or timeout)."""
        # DDS drops what is published before a reader matched; the probe's own reader not counted
        pub = self.node.create_publisher(msg_type, topic, 10)
        own = sum(1 for sub in self.node.subscriptions
                  if sub.topic_name == pub.topic_name)
        end = time.monotonic() + timeout
        while pub.get_subscription_count() - own < readers and time.monotonic() < end:
            self.spin(0.05)
        return pub

    def __enter__(self) -> 'Probe':
        """Return the probe; it is closed when the ``with`` block ends."""
        return self

    def __exit__(self, *exc) -> None:
        """Shut down the probe's executor, node and context."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
