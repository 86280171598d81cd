"""Fault injection: the entries parse or are refused, a latency delivers every message in order.

The latency's bookkeeping (:class:`LatencyLine`) is fed made-up times; its delivery on a
node's sim clock is driven by ``/clock`` messages the test publishes; the bridge's
``/joint_states`` publisher is checked for both its direct and its late path.
"""
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from scara_collab.nodes import conversions as conv
from scara_collab.nodes.faults import (declare_faults, Fault, FaultPlan, FaultyPublisher,
                                       LatencyLine, parse_faults)
from scara_collab.nodes.sim_timer import every


# --- parsing -------------------------------------------------------------------------------
def test_the_three_forms_parse():
    """drop, delay and latency entries parse into their faults; empty entries are ignored."""
    faults = parse_faults(['drop:/a/gripper:2', '', 'delay:/a/status:3:0.5',
                           'latency:/joint_states:0.02:0.01', 'latency:/b/status:0.03:0.03',
                           'latency:/c:0:0', 'drop:/joint_states:1'])
    assert faults['/a/gripper'] == [Fault('drop', 2)]
    assert faults['/a/status'] == [Fault('delay', 3, 0.5)]
    assert faults['/joint_states'] == [Fault('latency', 0, 0.02, 0.01), Fault('drop', 1)]
    assert faults['/b/status'] == [Fault('latency', 0, 0.03, 0.03)]  # jitter == mean: from 0
    assert faults['/c'] == [Fault('latency', 0, 0.0, 0.0)]
    plan = FaultPlan(['latency:/joint_states:0.02:0.01'])
    assert set(plan.latency) == {'/joint_states'}
    assert plan.next('/joint_states') is None  # a latency is the line's business, not next's


@pytest.mark.parametrize('spec, reason', [
    ('latency:/joint_states:0.01:0.02', 'jitter <= mean'),
    ('latency:/joint_states:-0.02:0.01', 'jitter <= mean'),
    ('latency:/joint_states:0.02:-0.01', '0 <= jitter'),
    ('latency:/joint_states:nan:0', '0 <= jitter <= mean'),
    ('latency:/joint_states:inf:0', '0 <= jitter <= mean'),
    ('latency:/joint_states:soon:0', '0 <= jitter <= mean'),
    ('latency:/joint_states:0.02', 'fully qualified name'),
    ('latency:/joint_states:0.02:0.01:3', 'fully qualified name'),
    ('latency:joint_states:0.02:0.01', 'fully qualified name'),
    ('lag:/joint_states:0.02:0.01', 'expected drop:/<name>:<N>, delay:'),
    ('drop:/a:-1', 'N >= 0'),
    ('drop:/a:1.5', 'N >= 0'),
    ('delay:/a:1:-0.5', 'seconds >= 0'),
    ('delay:/a:1', 'fully qualified name'),
])
def test_a_malformed_entry_is_refused_with_the_reason(spec, reason):
    """Each malformed entry is refused with a ValueError that names it and the rule."""
    with pytest.raises(ValueError, match='fault ' + repr(spec).replace('.', r'\.')) as exc:
        parse_faults([spec])
    assert reason in str(exc.value)


def test_a_second_latency_on_one_name_is_refused():
    """Two latencies on one name would be one latency: refused rather than guessed."""
    with pytest.raises(ValueError, match='a second latency for /joint_states'):
        parse_faults(['latency:/joint_states:0.02:0.01', 'latency:/joint_states:0.05:0'])


# --- the line, on made-up times ------------------------------------------------------------
def test_the_line_delivers_in_order_within_the_delay_bounds():
    """100 Hz sends, 20 +- 10 ms: each within its bounds, never before the one sent before.

    Due = max(previous due, sent + delay), delay uniform in [10, 30] ms; taken at 1 ms looks,
    each item leaves at the first look at or after its due time.
    """
    mean, jitter = 0.02, 0.01
    line = LatencyLine('/joint_states', mean, jitter)
    rng = np.random.default_rng(3)
    sent = np.cumsum(rng.uniform(0.002, 0.018, 2000))  # ~100 Hz, irregular
    due = np.array([line.push(t, k) for k, t in enumerate(sent)])
    assert len(line) == 2000
    assert np.all(np.diff(due) >= 0), 'due times never go back'
    late = due - sent
    assert np.all(late >= mean - jitter - 1e-12), late.min()
    # beyond mean + jitter only when held behind the one before (its due time)
    held = late > mean + jitter + 1e-12
    assert np.all(due[1:][held[1:]] == due[:-1][held[1:]]) and not held[0]
    free = late[~held]
    assert free.min() < mean - 0.9 * jitter and free.max() > mean + 0.9 * jitter
    assert abs(free.mean() - mean) < 0.001, free.mean()
    # taken at 1 ms looks: in order, each at the first look at or after its due time
    out, when = [], []
    for look in np.arange(0.0, sent[-1] + 0.1, 0.001):
        got = line.pop_due(look)
        out += got
        when += [look] * len(got)
    assert out == list(range(2000)) and not len(line)
    assert np.all(np.asarray(when) >= due - 1e-12)
    assert np.all(np.asarray(when) < due + 0.001 + 1e-9)


def test_the_delays_are_the_same_every_run_and_differ_per_name():
    """Seeded with the name: one run's delays are the next run's; another name's are not."""
    def delays(name):
        line = LatencyLine(name, 0.02, 0.01)
        return [line.push(0.01 * k, k) - 0.01 * k for k in range(50)]
    assert delays('/joint_states') == delays('/joint_states')
    assert delays('/joint_states') != delays('/scara_left/planner_status')
    fixed = LatencyLine('/x', 0.02, 0.0)
    assert [fixed.push(0.01 * k, k) for k in range(3)] == pytest.approx([0.02, 0.03, 0.04])


# --- on a node -----------------------------------------------------------------------------
class Spy:
    """A stand-in for a publisher: records ``(node's sim time, message)`` at each publish."""

    def __init__(self, node: Node, topic: str):
        """Record on ``node``'s clock; answer ``topic_name`` like an rclpy publisher."""
        self.node, self.topic_name, self.out = node, topic, []

    def publish(self, msg) -> None:
        """Record the message with the time it left."""
        self.out.append((conv.now(self.node), msg))


@pytest.fixture
def g():
    """Yield a test graph (its own context and executor), closed afterwards."""
    graph = Graph()
    yield graph
    graph.close()


def test_a_publisher_no_entry_names_publishes_directly():
    """No entry for its topic: ``publish`` is the publisher's own (no cost on a hot path)."""
    spy = Spy(None, '/joint_states')
    for specs in ([], ['drop:/scara_left/gripper:2', 'latency:/scara_left/planner_status:1:0']):
        direct = FaultyPublisher(None, FaultPlan(specs), spy)
        assert direct.publish == spy.publish and direct.topic_name == '/joint_states'
    faulty = FaultyPublisher(None, FaultPlan(['latency:/joint_states:0.02:0.01']), spy)
    assert faulty.publish != spy.publish


def test_on_sim_time_every_message_leaves_late_in_order_from_one_queue(g):
    """A node on sim time: messages sent each 10 ms leave in order, 10-30 ms late.

    A message leaves at the first ``/clock`` (or the next send) at or after its due time, so
    here at most one clock step (10 ms) after it. One queue and one look per name: the node
    gains one sim timer, however many messages wait. While the clock stands still, the
    messages in flight arrive within half a second (wall).
    """
    node = g.add(Node('late', context=g.context, parameter_overrides=[
        Parameter('use_sim_time', value=True),
        Parameter('faults', value=['latency:/late/status:0.02:0.01'])]))
    plan = declare_faults(node)
    spy = Spy(node, '/late/status')
    pub = FaultyPublisher(node, plan, spy)
    clock = g.probe.create_publisher(Clock, '/clock', 10)
    assert g.spin_until(lambda: clock.get_subscription_count() > 0, 10.0)
    sent = []
    for k in range(1, 121):
        t = round(0.01 * k, 6)
        clock.publish(Clock(clock=conv.to_time(t)))
        assert g.spin_until(lambda: abs(conv.now(node) - t) < 1e-9, 10.0), t
        if k <= 100:
            msg = JointState()
            msg.header.stamp = conv.to_time(t)
            pub.publish(msg)
            sent.append(t)
    assert len(getattr(node, 'sim_timers', [])) == 1
    assert [conv.to_sec(m.header.stamp) for _, m in spy.out] == pytest.approx(sent), 'order'
    late = np.array([left - conv.to_sec(m.header.stamp) for left, m in spy.out])
    assert late.min() >= 0.01 - 1e-9 and late.max() <= 0.03 + 0.01 + 1e-9, late
    assert plan.injected['/late/status'] == 100
    # the clock stops (a paused simulation): what is in flight arrives all the same
    pub.publish(JointState())
    assert g.spin_until(lambda: len(spy.out) == 101, 5.0), 'stuck while the clock stood still'
    assert spy.out[-1][0] == pytest.approx(1.2)


def test_the_bridge_publishes_joint_states_directly_or_late_in_order(g):
    """The bridge's ``/joint_states``: direct without a fault, late and in order with one.

    Without a fault ``publish`` is the publisher's own; with a latency every state leaves in
    order at the first value of the bridge's sim clock at or after its due time (the line's,
    drawn at the send).
    """
    from scara_collab.nodes.pybullet_bridge import PyBulletBridge

    def bridge(faults):
        return PyBulletBridge(context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={
                'real_time_factor': 1.0, 'feed_interval': 0.0, 'faults': faults}))
    plain = bridge([''])
    try:
        assert plain.outputs.state_pub.publish == plain.outputs.state_pub.publisher.publish
    finally:
        plain.destroy_node()
    late = g.add(bridge(['latency:/joint_states:0.02:0.01']))
    spy = late.outputs.state_pub.publisher = Spy(late, '/joint_states')  # what leaves, and when
    line, dues = late.faults.latency['/joint_states'], []
    before = line.sent  # the state the bridge sent as it started (due unknown here)
    push = line.push
    line.push = lambda now, item: dues.append(push(now, item)) or dues[-1]
    seen = [conv.now(late)]  # every value the bridge's clock takes from here on
    every(late, 1e-3, lambda: seen.append(conv.now(late)))
    assert g.spin_until(lambda: len(spy.out) >= 100, 30.0), len(spy.out)
    stamps = np.array([conv.to_sec(m.header.stamp) for _, m in spy.out])
    assert np.all(np.diff(stamps) > 0), 'in order'
    left = np.array([t for t, _ in spy.out])[before:]
    due = np.array(dues[:len(left)])
    assert np.all(left >= due - 1e-9), (left - due).min()
    seen = np.array(seen)
    first = [seen[seen >= d - 1e-9].min() for d in due]
    assert left.tolist() == pytest.approx(first), 'at the first clock at or after the due time'
    assert late.faults.injected['/joint_states'] >= 100
