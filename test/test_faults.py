"""Fault injection: the entries parse or are refused, a latency delivers every message in order.

The latency's bookkeeping (:class:`LatencyLine`) is fed made-up times; its delivery on a
node's sim clock is driven by ``/clock`` messages the test publishes; the bridge's
``/joint_states`` publisher is checked for both its direct and its late path. The hook wraps
a node from outside (no production module imports the fault module, and without faults it is
not even loaded); a crash is the supervisor's SIGKILL at a sim time.
"""
import ast
from pathlib import Path
import subprocess
import sys
import time

import numpy as np
import pytest
from rclpy.client import Client
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from scara_collab import graph
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.sim_timer import every
from scara_collab.run.faults import (Crash, crashes, Delay, Drop, FaultPlan, FaultyClient,
                                     FaultyPublisher, hook, Latency, LatencyLine, Loss,
                                     node_entries, parse_faults, plan_of, Repeat, with_faults)

PACKAGE = Path(__file__).resolve().parents[1] / 'scara_collab'


# --- parsing -------------------------------------------------------------------------------
def test_the_forms_parse():
    """Every form parses into its typed record, one meaning per field; empty entries go."""
    faults = parse_faults(['drop:/a/gripper:2', '', 'delay:/a/status:3:0.5',
                           'latency:/joint_states:0.02:0.01', 'latency:/b/status:0.03:0.03',
                           'latency:/c:0:0', 'drop:/joint_states:1', 'loss:/d:0.3',
                           'repeat:/d:1', 'crash:/cell_1/pybullet_bridge:35'])
    assert faults['/a/gripper'] == [Drop(2)]
    assert faults['/a/status'] == [Delay(3, 0.5)]
    assert faults['/joint_states'] == [Latency(0.02, 0.01), Drop(1)]
    assert faults['/b/status'] == [Latency(0.03, 0.03)]  # jitter == mean: from 0
    assert faults['/c'] == [Latency(0.0, 0.0)]
    assert faults['/d'] == [Loss(0.3), Repeat(1.0)]
    assert faults['/cell_1/pybullet_bridge'] == [Crash(35.0)]
    plan = FaultPlan(['latency:/joint_states:0.02:0.01'])
    assert set(plan.latency) == {'/joint_states'}
    assert plan.next('/joint_states') is None  # a latency is the line's business, not next's
    # the crashes are the supervisor's: a node's plan and its entries leave them out
    specs = ['crash:/cell_1/pybullet_bridge:35', 'drop:/a/gripper:2']
    assert crashes(specs) == {'/cell_1/pybullet_bridge': 35.0}
    assert node_entries(specs) == ['drop:/a/gripper:2']
    assert set(FaultPlan(specs).faults) == {'/a/gripper'}


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
    ('loss:/a:1.5', '0 <= p <= 1'),
    ('repeat:/a:-0.1', '0 <= p <= 1'),
    ('crash:/a:-1', 'sim seconds >= 0'),
    ('crash:/a', 'fully qualified name'),
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
    """No entry for its topic: the plan hands back the publisher itself (no cost on a hot path)."""
    spy = Spy(None, '/joint_states')
    for specs in ([], ['drop:/scara_left/gripper:2', 'latency:/scara_left/planner_status:1:0']):
        assert FaultPlan(specs).publisher(None, spy) is spy
    faulty = FaultPlan(['latency:/joint_states:0.02:0.01']).publisher(None, spy)
    assert isinstance(faulty, FaultyPublisher) and faulty.publish != spy.publish
    assert faulty.topic_name == '/joint_states'  # the rest is the publisher's


def test_on_sim_time_every_message_leaves_late_in_order_from_one_queue(g):
    """A node on sim time: messages sent each 10 ms leave in order, 10-30 ms late.

    A message leaves at the first ``/clock`` (or the next send) at or after its due time, so
    here at most one clock step (10 ms) after it. One queue and one look per name: the node
    gains one sim timer, however many messages wait. While the clock stands still, the
    messages in flight arrive within half a second (wall).
    """
    node = g.add(with_faults(Node, ['latency:/late/status:0.02:0.01'])(
        'late', context=g.context, parameter_overrides=[Parameter('use_sim_time', value=True)]))
    plan = plan_of(node)
    spy = Spy(node, '/late/status')
    pub = plan.publisher(node, spy)
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
    spec = graph.node('pybullet_bridge')

    def bridge(wrap):
        return spec.build(wrap, context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={
                'real_time_factor': 1.0, 'feed_interval': 0.0}))
    plain = bridge(None)
    try:  # the class itself, its own rclpy publisher
        assert type(plain) is spec.node_class() and plan_of(plain) is None
        assert type(plain.outputs.state_pub) is Publisher
    finally:
        plain.destroy_node()
    late = g.add(bridge(hook(['latency:/joint_states:0.02:0.01'])))
    assert isinstance(late, spec.node_class()) and type(late).__name__ == 'PyBulletBridge'
    assert isinstance(late.outputs.state_pub, FaultyPublisher)
    assert type(late.outputs.clock_pub) is Publisher  # no entry names it: plain
    spy = late.outputs.state_pub.publisher = Spy(late, '/joint_states')  # what leaves, and when
    line, dues = plan_of(late).latency['/joint_states'], []
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
    assert plan_of(late).injected['/joint_states'] >= 100


# --- the hook: from outside, per node --------------------------------------------------------
def test_each_node_has_its_own_plan_and_the_first_n_are_its_own(g):
    """Two nodes built with one hook: each loses its own first two messages of the topic."""
    wrap = hook(['drop:/shared/status:2', 'crash:/a:1'])
    nodes = [g.add(wrap(Node)(name, context=g.context)) for name in ('a', 'b')]
    plans = [plan_of(n) for n in nodes]
    assert plans[0] is not plans[1] and set(plans[0].faults) == {'/shared/status'}
    spies = [Spy(n, '/shared/status') for n in nodes]
    pubs = [p.publisher(n, s) for p, n, s in zip(plans, nodes, spies)]
    for k in range(5):
        pubs[0].publish(k)
    pubs[1].publish(10)
    assert [m for _, m in spies[0].out] == [2, 3, 4] and spies[1].out == []
    # every publisher and client the node makes goes through its plan
    real = nodes[0].create_publisher(JointState, '/shared/status', 10)
    assert isinstance(real, FaultyPublisher) and isinstance(real.publisher, Publisher)
    assert type(nodes[0].create_publisher(JointState, '/other', 10)) is Publisher


def test_a_lost_response_never_completes_its_future_and_the_next_one_does(g):
    """``drop:/<service>:1``: the server answers, the first response never arrives.

    A repeated response runs the future's callbacks again; a client no entry names is the
    node's own.
    """
    server = g.add(Node('server', context=g.context))
    served = []

    def answer(req, res):
        served.append(1)
        res.success, res.message = True, f'answer {len(served)}'
        return res
    server.create_service(Trigger, '/ask', answer)
    node = g.add(with_faults(Node, ['drop:/ask:1', 'repeat:/again:1'])('client',
                                                                       context=g.context))
    cli = node.create_client(Trigger, 'ask')
    assert isinstance(cli, FaultyClient) and cli.srv_name == 'ask'
    assert type(node.create_client(Trigger, '/plain')) is Client
    assert g.spin_until(cli.service_is_ready, 10.0)
    lost = cli.call_async(Trigger.Request())
    assert g.spin_until(lambda: len(served) == 1, 10.0)
    assert not g.spin_until(lost.done, 0.5), 'the lost response arrived'
    got = cli.call_async(Trigger.Request())
    assert g.spin_until(got.done, 10.0) and got.result().message == 'answer 2'
    assert plan_of(node).injected == {'/ask': 1}
    server.create_service(Trigger, '/again', answer)
    twice = node.create_client(Trigger, '/again')
    assert g.spin_until(twice.service_is_ready, 10.0)
    seen = []
    future = twice.call_async(Trigger.Request())
    future.add_done_callback(lambda f: seen.append(f.result().message))
    assert g.spin_until(lambda: len(seen) == 2, 10.0) and seen[0] == seen[1] == 'answer 3'


def _imports(path: Path):
    """Yield the modules ``path`` imports (``from x import y`` as ``x`` and ``x.y``)."""
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
            yield from (f'{node.module}.{a.name}' for a in node.names)


def test_no_production_module_imports_the_fault_injection():
    """Nodes, core and sim know nothing of the fault module: it wraps them from outside."""
    assert not (PACKAGE / 'nodes' / 'faults.py').exists()
    offenders = [f'{path.relative_to(PACKAGE.parent)}: {name}'
                 for layer in ('nodes', 'core', 'sim') for path in (PACKAGE / layer).rglob('*.py')
                 for name in _imports(path) if name.split('.')[-1] == 'faults'
                 or name.startswith('scara_collab.run')]
    assert offenders == []


def test_without_faults_the_fault_module_is_not_loaded():
    """The launcher, its node processes and the in-process job import it only for faults."""
    modules = ['scara_collab.run.launcher', 'scara_collab.run.child',
               'scara_collab.run.container', 'scara_collab.run.stages',
               'scara_collab.run.supervisor', 'scara_collab.run.options',
               'benchmarks.job_in_process']
    modules += sorted({spec.component.split(':')[0] for spec in graph.NODES})
    code = (f'import importlib, sys\nfor m in {modules!r}:\n    importlib.import_module(m)\n'
            'from scara_collab.run import options, stages\n'
            'stages.stages(options.parse_options([]), True)\n'
            "print('scara_collab.run.faults' in sys.modules)")
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120, cwd=PACKAGE.parent)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'False'


# --- the launcher's side: entries to the processes, crashes to the supervisor ----------------
def test_the_processes_get_the_node_entries_and_the_bridge_pauses_where_it_dies():
    """Each node process gets ``--fault`` pairs before its ``--ros-args``, never a crash.

    A crash of this cell's bridge also becomes its ``pause_at``; another cell's is not this
    cell's.
    """
    from scara_collab.run import container, stages as plan
    from scara_collab.run.child import take_faults
    from scara_collab.run.options import parse_options
    args = parse_options(['--duration', '60', '--fault', 'drop:/scara_left/gripper:1',
                          '--fault', 'crash:/pybullet_bridge:35', '--fault',
                          'crash:/cell_1/left_planner:5'])
    assert plan.crashes(args) == {'pybullet_bridge': 35.0}
    stages = plan.stages(args, True)
    assert stages[0].params['pause_at'] == '35.0'
    cmd = plan.command(stages[1], Path('/cfg'))
    assert take_faults(cmd[4:]) == (['drop:/scara_left/gripper:1'],
                                    plan.node_args(stages[1], Path('/cfg')))
    one = plan.command(plan.one_process(stages), Path('/cfg'))
    faults, rest = take_faults(one[3:])
    assert faults == ['drop:/scara_left/gripper:1'] and container.parse(rest)[0][0] == \
        stages[0].entry
    args = parse_options(['--duration', '60', '--cells', '3', '--line-cell', '1',
                          '--fault', 'crash:/cell_1/pybullet_bridge:35',
                          '--fault', 'crash:/cell_2/pybullet_bridge:20'])
    assert plan.crashes(args) == {'pybullet_bridge': 35.0}
    assert plan.stages(args, True)[0].params['pause_at'] == '35.0'
    assert all(s.faults == () for s in plan.stages(args, True))
    assert parse_options(['--duration', '30', '--fault', 'crash:/pybullet_bridge:45']
                         ).faults  # beyond the run: it never comes
    assert plan.stages(parse_options(['--duration', '30', '--fault',
                                      'crash:/pybullet_bridge:45']), True)[0].params[
        'pause_at'] == '30.0'


def test_the_supervisor_kills_the_process_when_sim_time_reaches_the_crash(tmp_path):
    """SIGKILL at T, not before; the log and the run's end say so."""
    from scara_collab.run.console import Console
    from scara_collab.run.stages import Stage
    from scara_collab.run.supervisor import Child, RunEnd, Supervisor
    console = Console(tmp_path / 'launch.log', quiet=True)
    sup = Supervisor(tmp_path, tmp_path, console, {'left_planner': 5.0})
    log = tmp_path / 'left_planner.log'
    proc = subprocess.Popen(['sleep', '60'])
    try:
        sup.children.append(Child(Stage('left_planner', 'm:f', (), 'ready'), proc, log,
                                  open(log, 'wb'), time.monotonic()))
        sup.crash_due(4.99)
        sup.check()
        assert proc.poll() is None and sup.crashes
        sup.crash_due(5.0)
        assert proc.returncode == -9 and not sup.crashes
        with pytest.raises(RunEnd, match=r'node left_planner was killed at sim t=5\.000 s'):
            sup.check()
        sup.children[0].log_file.close()
        assert 'fault injection: crash of left_planner at sim t=5.000 s' in log.read_text()
    finally:
        proc.kill()
        proc.wait()
        console.close()


def test_a_slip_is_the_worlds_fault_for_the_bridge_not_a_nodes():
    """``drop@T`` and ``drop@rate:R`` reach the bridge as parameters, no node applies them."""
    from scara_collab.run import stages as plan
    from scara_collab.run.faults import node_entries, slips
    from scara_collab.run.options import parse_options
    specs = ['drop@30', 'drop@12.5', 'drop@rate:0.1', 'drop:/scara_left/gripper:1']
    assert slips(specs) == ([12.5, 30.0], 0.1)
    assert node_entries(specs) == ['drop:/scara_left/gripper:1']
    bridge = plan.stages(parse_options(['--duration', '60'] + [
        a for s in specs for a in ('--fault', s)]), True)[0].params
    assert bridge['slip_at'] == '12.5,30.0' and bridge['slip_rate'] == '0.1'
    for bad in ('drop@-1', 'drop@soon', 'drop@rate:x'):
        with pytest.raises(ValueError, match='expected drop@'):
            slips([bad])
