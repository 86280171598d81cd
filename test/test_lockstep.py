"""Lockstep: the bridge holds sim time while a participant computes, and never hangs on one.

The bridge spins in the test's thread; a participant node spins in its own executor thread and
blocks in one of its ``/clock`` callbacks, the way a planner blocks while it plans.
"""
import threading
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock

from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.pybullet_bridge import PyBulletBridge


class Busy:
    """A participant that, once sim time passes ``after``, computes for ``seconds`` (wall)."""

    def __init__(self, g: Graph, after: float, seconds: float):
        self.node = Node('busy', context=g.context,
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.part = lockstep.join(self.node)
        self.after, self.seconds = after, seconds
        self.window = None  # (sim time of the clock that started the work, bridge time at end)
        self.bridge = g.bridge
        self.node.create_subscription(Clock, '/clock', self._on_clock, 1)
        self.executor = SingleThreadedExecutor(context=g.context)
        self.executor.add_node(self.node)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.01)

    def _on_clock(self, msg: Clock) -> None:
        t = conv.to_sec(msg.clock)
        if self.window is None and t >= self.after:
            time.sleep(self.seconds)
            self.window = (t, self.bridge.sim.time)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5.0)
        self.executor.shutdown()
        self.node.destroy_node()


def make_graph(window: float, timeout: float = 5.0) -> Graph:
    g = Graph()
    g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
        'simulation', 'controllers', overrides={
            'real_time_factor': 0.0, 'feed_interval': 0.0, 'lockstep_window': window,
            'lockstep_timeout': timeout})))
    return g


@pytest.mark.parametrize('window', [0.02, 0.0])
def test_sim_time_waits_for_a_busy_participant(window):
    g = make_graph(window)
    busy = Busy(g, after=0.3, seconds=0.6)
    try:
        assert g.spin_until(lambda: busy.window is not None, 30.0)
        t_clock, t_after = busy.window
        advance = t_after - t_clock
        if window > 0:
            # at most the window beyond its last answer (which was at most one clock earlier)
            assert advance <= window + 0.0105, advance
        else:  # no gate: physics ran on unthrottled while the node was busy
            assert advance > 0.2, advance
        assert g.spin_until(lambda: g.bridge.sim.time > t_after + 0.3, 20.0), 'sim went on'
        if window > 0:
            assert g.bridge.gate.waited.get('/busy', 0.0) > 0.4, g.bridge.gate.summary()
    finally:
        busy.close()
        g.close()


def test_a_silent_participant_is_dropped_and_rejoins():
    g = make_graph(0.02, timeout=0.3)
    busy = Busy(g, after=0.2, seconds=1.5)
    try:
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.dropped, 20.0)
        t_dropped = g.bridge.sim.time
        assert g.spin_until(lambda: g.bridge.sim.time > t_dropped + 0.2, 10.0)
        assert busy.window is None, 'the bridge went on while the node was still busy'
        assert g.spin_until(lambda: busy.window is not None, 20.0)
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.reached, 10.0), 'rejoined'
        assert '/busy' not in g.bridge.gate.dropped
    finally:
        busy.close()
        g.close()


def test_a_leaving_participant_is_no_longer_waited_for():
    g = make_graph(0.02, timeout=30.0)
    busy = Busy(g, after=1e9, seconds=0.0)  # never busy
    try:
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.reached, 20.0)
        busy.stop.set()
        busy.thread.join(5.0)
        lockstep.leave(busy.node)
        assert g.spin_until(lambda: '/busy' not in g.bridge.gate.reached, 10.0)
        t = g.bridge.sim.time
        # the participant no longer spins; with a 30 s timeout only its leaving frees the clock
        assert g.spin_until(lambda: g.bridge.sim.time > t + 0.5, 10.0)
    finally:
        busy.close()
        g.close()


def test_nodes_on_wall_time_or_opted_out_do_not_join():
    g = Graph()
    try:
        wall = Node('wall', context=g.context)
        out = Node('out', context=g.context, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('lockstep', value=False)])
        assert lockstep.join(wall) is None and lockstep.join(out) is None
        wall.destroy_node()
        out.destroy_node()
    finally:
        g.close()


def test_a_window_shorter_than_the_clock_period_is_refused():
    g = Graph()
    try:
        with pytest.raises(ValueError, match='clock could never advance'):
            PyBulletBridge(context=g.context, cli_args=params_args(
                'simulation', 'controllers', overrides={'lockstep_window': 0.005}))
    finally:
        g.close()
