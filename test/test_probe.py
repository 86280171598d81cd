"""The fault matrix's probe: an injection waits for the graph's readers, not for its own."""
import time

import rclpy
from sensor_msgs.msg import JointState

from benchmarks.probe import Probe


def test_a_probe_publisher_waits_for_the_graphs_readers_not_its_own():
    """The probe's own /joint_states subscription does not count as a reader of it.

    Counting it made every /joint_states injection start at once, before the launched nodes
    had matched: most of the forged states reached nobody.
    """
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    other = rclpy.create_node('reader', context=ctx)
    try:
        with Probe() as probe:
            t0 = time.monotonic()
            other.create_subscription(JointState, '/joint_states', lambda m: None, 1)
            pub = probe.publisher(JointState, '/joint_states', readers=1, timeout=10.0)
            assert pub.get_subscription_count() >= 2  # the probe's own and the other node's
            assert time.monotonic() - t0 < 9.0  # matched, not timed out
            t0 = time.monotonic()  # there is no second reader: it waits the whole timeout
            probe.publisher(JointState, '/joint_states', readers=2, timeout=1.0)
            assert time.monotonic() - t0 >= 1.0
    finally:
        other.destroy_node()
        rclpy.try_shutdown(context=ctx)
