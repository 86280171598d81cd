"""The collision monitor alone: it fails closed, recovers, and reports the separation's source."""
import numpy as np
import pytest
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from scara_collab.core.mirror import mirror_joints
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.collision_monitor import CollisionMonitor

HOME = np.array([0.0, 1.5708, 0.0])


@pytest.fixture
def graph(cell):
    g = Graph()
    g.cell = cell
    g.monitor = g.add(CollisionMonitor(context=g.context, cli_args=params_args(
        overrides={'use_sim_time': 'true', 'lockstep': 'false'})))
    g.clock = g.probe.create_publisher(Clock, '/clock', 10)
    g.states = g.probe.create_publisher(JointState, '/joint_states', 10)
    assert g.spin_until(lambda: g.states.get_subscription_count() > 0
                        and g.clock.get_subscription_count() > 0)
    yield g
    g.close()


def state(cell, t, q_left, q_right=None, nan=False):
    names = list(cell.leader.joint_names) + list(cell.follower.joint_names)
    q_right = mirror_joints(q_left) if q_right is None else q_right
    pos = list(q_left) + list(q_right)
    if nan:
        pos[1] = float('nan')
    return conv.joint_state(t, names, pos, [0.0] * 6, [0.0] * 6)


def tick(g, t):
    g.clock.publish(Clock(clock=conv.to_time(t)))
    assert g.spin_until(lambda: abs(g.monitor._now() - t) < 1e-9)


def test_a_state_before_the_first_clock_does_not_trip_the_watchdog(graph):
    g = graph
    g.states.publish(state(g.cell, 0.0, HOME))
    assert g.spin_until(lambda: g.monitor.last is not None)
    tick(g, 12.0)  # the launch: sim time jumps to the bridge's clock
    g.spin_until(lambda: False, timeout=0.3)
    assert not g.monitor.stopped, g.monitor.reason


def test_fails_closed_on_a_nan_state_and_on_silence_then_clears(graph):
    g = graph
    tick(g, 1.0)
    g.states.publish(state(g.cell, 1.0, HOME, nan=True))
    assert g.spin_until(lambda: g.monitor.stopped)
    assert 'unusable joint state' in g.monitor.reason
    # a fresh, valid, separated state: clear succeeds (idempotent afterwards)
    g.states.publish(state(g.cell, 1.01, HOME))
    assert g.spin_until(lambda: g.monitor.last is not None)
    res = g.call(Trigger, '/collision_monitor/clear', Trigger.Request())
    assert res.success and not g.monitor.stopped
    assert g.call(Trigger, '/collision_monitor/clear', Trigger.Request()).success
    # sim time runs on without states: the watch fails closed
    for t in (1.1, 1.2, 1.3, 1.4, 1.5):
        tick(g, t)
    assert g.spin_until(lambda: g.monitor.stopped, timeout=5.0)
    assert 'no valid joint state' in g.monitor.reason
    st = g.monitor.status()
    assert st.stopped and st.minimum is not None and st.minimum > 0.1
