"""A periodic callback on sim time runs from the clock, on a timer's grid, before the answer."""
import gc

import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.timer import Timer
from ros_harness import Graph
from rosgraph_msgs.msg import Clock

from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.sim_timer import every, SimTimer


@pytest.fixture
def g():
    """Yield a test graph (its own context and executor), closed afterwards."""
    graph = Graph()
    yield graph
    graph.close()


def sim_node(g: Graph, name: str) -> Node:
    """Add a node on sim time named ``name`` to ``g``."""
    return g.add(Node(name, context=g.context,
                      parameter_overrides=[Parameter('use_sim_time', value=True)]))


def run_clock(g: Graph, node: Node, times) -> None:
    """Publish each ``/clock`` and spin until ``node``'s clock has taken it."""
    pub = g.probe.create_publisher(Clock, '/clock', 10)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0, 10.0)
    for t in times:
        pub.publish(Clock(clock=conv.to_time(t)))
        assert g.spin_until(lambda: abs(conv.now(node) - t) < 1e-9, 10.0), t


def test_it_fires_on_the_period_grid_once_per_jump(g):
    """Like a timer: at the first clock at or past each call, once however far time jumps."""
    node = sim_node(g, 'ticking')
    seen = []
    timer = every(node, 0.05, lambda: seen.append(round(conv.now(node), 6)))
    assert isinstance(timer, SimTimer)
    run_clock(g, node, [round(0.02 * k, 6) for k in range(1, 26)])  # 0.02 .. 0.50
    assert seen == [0.06, 0.1, 0.16, 0.2, 0.26, 0.3, 0.36, 0.4, 0.46, 0.5]
    run_clock(g, node, [2.0, 2.03, 2.05])  # a jump of 1.5 s: one call, then on the grid
    assert seen[10:] == [2.0, 2.05]


def test_an_exception_does_not_escape_and_the_next_call_comes(g):
    """A failing callback is logged (guarded); the node and the timer live on."""
    node = sim_node(g, 'failing')
    calls = []

    def fail():
        calls.append(conv.now(node))
        raise RuntimeError('boom')
    every(node, 0.02, fail)  # not kept by the caller: the node keeps it
    gc.collect()
    run_clock(g, node, [0.02, 0.04, 0.06])
    assert len(calls) == 3


def test_created_before_joining_the_lockstep_it_runs_before_the_answer(g):
    """The node answers a /clock only after its tick for that instant has run."""
    node = sim_node(g, 'job')
    answered_at_tick, parts = [], []
    every(node, 0.02, lambda: answered_at_tick.append(parts[0].answered))
    part = lockstep.join(node)
    parts.append(part)
    run_clock(g, node, [0.02, 0.04, 0.06])
    assert answered_at_tick == [0, 1, 2]  # the answer to the same clock comes after
    assert part.answered == 3


def test_on_wall_time_it_is_an_ordinary_timer(g):
    """A node on wall time gets an rclpy timer."""
    node = g.add(Node('walltime', context=g.context))
    calls = []
    timer = every(node, 0.01, lambda: calls.append(1))
    assert isinstance(timer, Timer)
    assert g.spin_until(lambda: len(calls) >= 3, 5.0)
