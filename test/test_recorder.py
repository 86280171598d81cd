"""The run recorder and report: CSV rows and values, summary, plots, interrupted runs."""
import csv
import json
import math

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.time import Time as RclpyTime
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from scara_collab.core.collision import arm_distance
from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_joints, mirror_point
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.recorder import RunRecorder
from scara_collab.records import report
from scara_collab.records.telemetry import parse_value, RunLog, state_columns

PNG = b'\x89PNG\r\n\x1a\n'
SUMMARY_KEYS = ('mode', 'sim_seconds', 'wall_seconds', 'sorted', 'missed', 'wrong_bin',
                'items_per_minute', 'min_separation_m', 'mirror_error_max_m',
                'real_time_factor', 'interrupted', 'exit_reason', 'job', 'counts_source',
                'min_separation_source')


@pytest.fixture
def make_recorder(context, tmp_path, cell):
    """Yield ``make(mode, sub, **kwargs)``, a factory of recorders writing under ``tmp_path``.

    Every recorder it made is destroyed afterwards.
    """
    made = []

    def make(mode='collaborative', sub='run', **kwargs):
        rec = RunRecorder(tmp_path / sub, mode, cell=cell, context=context, **kwargs)
        made.append(rec)
        return rec

    yield make
    for rec in made:
        rec.destroy_node()


def random_joints(cell, n, seed=1):
    """Return ``n`` random joint states ``(n, 3)`` within 90 % of the leader's limits."""
    rng = np.random.default_rng(seed)
    arm = cell.leader
    return rng.uniform(arm.lower * 0.9, arm.upper * 0.9, size=(n, 3))


def state_msg(cell, t, q_lead, q_foll, reverse=False):
    """Return a JointState of both arms at ``t`` (``reverse``: the joints in reverse order)."""
    names = list(cell.leader.joint_names) + list(cell.follower.joint_names)
    pos = list(q_lead) + list(q_foll)
    if reverse:  # any joint order must work
        names, pos = names[::-1], pos[::-1]
    return conv.joint_state(t, names, pos, [0.0] * 6, [0.0] * 6)


def feed(rec, msg):
    """Hand ``rec`` a joint state as the graph would: /clock at its stamp first."""
    rec.get_clock().set_ros_time_override(RclpyTime.from_msg(msg.header.stamp))
    rec.on_joint_state(msg)


def event_msg(kind, t, item, cls='red', robot=''):
    """Return an item event as the bridge publishes it."""
    return proto.ItemEvent(kind, item, cls, t, robot).to_msg()


def read_csv(path):
    """Return the header and the rows of a CSV file."""
    with open(path, newline='') as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def assert_png(path):
    """Assert that ``path`` is a PNG file of a plausible size."""
    data = path.read_bytes()
    assert data.startswith(PNG), path
    assert len(data) > 5000, f'{path} is suspiciously small'


def test_state_rows_match_the_core(make_recorder, cell):
    """Each CSV row holds the state's time and joints and the core's figures, in any order.

    The tool tips, mirror error and arm distance are those of FK, ``mirror_point`` and
    ``arm_distance``.
    """
    rec = make_recorder('collaborative', batch=7)
    ql = random_joints(cell, 25, seed=2)
    qf = random_joints(cell, 25, seed=3)
    for k in range(25):
        feed(rec, state_msg(cell, 0.01 * k, ql[k], qf[k], reverse=k % 2 == 1))
    rec.log.flush()
    header, rows = read_csv(rec.directory / 'timeseries.csv')
    assert header == state_columns(cell)
    assert len(rows) == 25 and all(len(r) == len(header) for r in rows)
    data = np.array(rows, dtype=float)
    col = {name: k for k, name in enumerate(header)}
    np.testing.assert_allclose(data[:, col['t']], 0.01 * np.arange(25), atol=1e-4)
    joints = [col[n] for n in cell.leader.joint_names + cell.follower.joint_names]
    np.testing.assert_allclose(data[:, joints], np.hstack([ql, qf]), atol=1e-6)
    lead, foll = cell.leader, cell.follower
    p_l, p_f = fk(lead, ql), fk(foll, qf)
    tool = [col[f'{lead.name}_tool_{a}'] for a in 'xyz']
    np.testing.assert_allclose(data[:, tool], p_l, atol=1e-6)
    tool = [col[f'{foll.name}_tool_{a}'] for a in 'xyz']
    np.testing.assert_allclose(data[:, tool], p_f, atol=1e-6)
    err = np.linalg.norm(p_f - mirror_point(lead, foll, p_l), axis=1)
    np.testing.assert_allclose(data[:, col['mirror_error_m']], err, atol=1e-8)
    dist = np.array([arm_distance(lead, a, foll, b) for a, b in zip(ql, qf)])
    np.testing.assert_allclose(data[:, col['arm_distance_m']], dist, atol=1e-6)
    assert rec.log.min_distance == pytest.approx(dist.min(), abs=1e-12)


def test_mirrored_states_have_zero_mirror_error(make_recorder, cell):
    """Mirrored states give zero mirror error over the whole run; every plot is written."""
    rec = make_recorder('mirrored')
    q = random_joints(cell, 50, seed=4)
    for k in range(50):
        feed(rec, state_msg(cell, 0.01 * k, q[k], mirror_joints(q[k])))
    rec.log.flush()
    header, rows = read_csv(rec.directory / 'timeseries.csv')
    err = np.array([float(r[header.index('mirror_error_m')]) for r in rows])
    assert len(err) == 50 and np.all(err < 1e-9)
    summary = rec.finish('duration reached', False)
    assert summary['mirror_error_whole_run_max_m'] < 1e-9
    assert summary['mirror_error_max_m'] is None  # no replication manager heard
    assert [p.name for p in rec.plots] == list(report.PLOTS)
    for p in rec.plots:
        assert_png(p)


def test_summary_plots_and_counts(make_recorder, cell):
    """The summary counts the job window's events and takes the separation from the states.

    It writes its plots (no mirror plot outside mirrored mode), the events CSV and a report.
    """
    rec = make_recorder('collaborative')
    q = np.array([0.0, 1.5708, 0.0])
    for k in range(301):
        feed(rec, state_msg(cell, 10.0 + 0.01 * k, q, mirror_joints(q)))
        if k == 100:
            rec.start_job(11.0)
    for t, kind, item in ((10.5, 'spawned', 1), (11.5, 'spawned', 2), (12.0, 'sorted', 2),
                          (12.5, 'missed', 1), (12.6, 'grasped', 3)):
        rec.on_event(event_msg(kind, t, item, robot='scara_left' if kind == 'sorted' else ''))
    summary = rec.finish('duration reached', False)
    for key in SUMMARY_KEYS:
        assert key in summary, key
    assert summary['mode'] == 'collaborative' and summary['interrupted'] is False
    assert summary['sim_seconds'] == pytest.approx(2.0)
    assert summary['counts_source'] == 'pybullet_bridge /conveyor/events in the job window'
    assert all(summary[k] == summary['events'][k] for k in summary['events'])
    # the window starts at the job: the item spawned before it is not counted
    assert (summary['spawned'], summary['sorted'], summary['missed']) == (1, 1, 1)
    assert summary['items_per_minute'] == pytest.approx(30.0)
    assert summary['mirror_error_max_m'] is None
    assert summary['min_separation_m'] == pytest.approx(  # no monitor heard: the states'
        float(arm_distance(cell.leader, q, cell.follower, mirror_joints(q))))
    assert summary['min_separation_source'].startswith('recorded joint states')
    assert summary['margin_ok'] is True and summary['joint_state_rows'] == 301
    on_disk = json.loads((rec.directory / 'summary.json').read_text())
    assert on_disk['plots'] == list(report.PLOTS[:3])
    assert not (rec.directory / 'mirror_error.png').exists()
    for name in report.PLOTS[:3]:
        assert_png(rec.directory / name)
    _, events = read_csv(rec.directory / 'events.csv')
    assert events[2] == ['12.000', 'sorted', '2', 'red', 'scara_left', '']
    text = report.format_report(on_disk)
    assert 'sorted 1' in text and 'min arm sep.' in text and str(rec.directory) in text


def test_events_of_the_window_heard_after_it_closed_still_count(make_recorder, cell):
    """Events stamped within the window count after it is frozen; later ones do not.

    The state of the end can come before the window's last events (two topics, a starved
    launcher).
    """
    rec = make_recorder('collaborative')
    q = np.array([0.0, 1.5708, 0.0])
    rec.start_job(0.0)
    for k in range(201):
        feed(rec, state_msg(cell, 0.01 * k, q, mirror_joints(q)))
    rec.on_event(event_msg('spawned', 0.5, 1))
    rec.freeze(2.0)
    rec.on_event(event_msg('sorted', 1.98, 1, robot='scara_left'))  # in flight at the end
    rec.on_event(event_msg('spawned', 2.1, 2))  # after the window
    summary = rec.finish('duration reached', False)
    assert (summary['spawned'], summary['sorted']) == (1, 1)
    _, events = read_csv(rec.directory / 'events.csv')
    assert [e[1] for e in events] == ['spawned', 'sorted']


def test_each_figure_comes_from_its_one_source(make_recorder, cell):
    """Counts come from the events, give-ups from the job, the separation from the monitor."""
    rec = make_recorder('single')
    q = np.array([0.3, 1.0, 0.1])
    feed(rec, state_msg(cell, 1.0, q, mirror_joints(q)))
    rec.on_event(event_msg('sorted', 1.0, 1))
    rec.on_stats(proto.JobStats('single', True, 2.0, 0.0, {'sorted': 7, 'missed': 1},
                                give_ups=2, retries=5).to_msg())
    rec.on_monitor(proto.MonitorStatus(2.0, 0.9, 0.42, 1.5, 0.1, False).to_msg())
    feed(rec, state_msg(cell, 2.0, q, mirror_joints(q)))
    summary = rec.finish('duration reached', False, plots=False)
    assert (summary['sorted'], summary['missed']) == (1, 0)  # the events, not the job's view
    assert summary['job']['give_ups'] == 2 and summary['job']['retries'] == 5
    assert summary['min_separation_m'] == 0.42 and summary['min_separation_time'] == 1.5
    assert summary['min_separation_source'] == 'collision_monitor'
    json.loads((rec.directory / 'summary.json').read_text())


def test_mirrored_summary_takes_the_replication_managers_in_step_error(make_recorder, cell):
    """A mirrored summary reports the replication manager's in-step error."""
    rec = make_recorder('mirrored')
    q = np.array([0.3, 1.0, 0.1])
    feed(rec, state_msg(cell, 1.0, q, mirror_joints(q)))
    feed(rec, state_msg(cell, 1.01, q, mirror_joints(q + 0.2)))  # one arm parks
    rec.on_mirror(proto.MirrorStatus(True, 1.0, 0.0, 0.0009, 0.5, 3, 1, 'yielded').to_msg())
    summary = rec.finish('duration reached', False, plots=False)
    assert summary['mirror_error_max_m'] == pytest.approx(0.0009)
    assert summary['mirror_error_source'] == 'replication_manager, in-step moves'
    assert summary['mirror_not_in_step'] == 1
    assert summary['mirror_error_whole_run_max_m'] > 0.1
    assert summary['mirror_error_whole_run_time'] == pytest.approx(1.01)
    text = report.format_report(summary)
    assert 'max 0.90 mm over 3 moves the arms ran in step (1 not in step)' in text


def test_interrupted_recording_keeps_complete_files(make_recorder, cell):
    """An interrupted recording keeps every complete row and a summary marked interrupted.

    States that come after the close are ignored.
    """
    rec = make_recorder('collaborative', batch=10)
    q = random_joints(cell, 37, seed=5)
    for k in range(37):  # 3 full batches on disk, 7 rows still queued
        feed(rec, state_msg(cell, 0.01 * k, q[k], mirror_joints(q[k])))
    rec.on_event(event_msg('spawned', 0.2, 1))
    header, rows = read_csv(rec.directory / 'timeseries.csv')
    assert len(rows) == 30  # flushed as it goes, before any close
    rec.checkpoint()
    partial = json.loads((rec.directory / 'summary.json').read_text())
    assert partial['interrupted'] is True and partial['exit_reason'] == 'running'
    rec.close()  # no finish(): the launcher died or the test ended early
    text = (rec.directory / 'timeseries.csv').read_text()
    assert text.endswith('\n')
    header, rows = read_csv(rec.directory / 'timeseries.csv')
    assert len(rows) == 37 and all(len(r) == len(header) for r in rows)
    summary = json.loads((rec.directory / 'summary.json').read_text())
    assert summary['interrupted'] is True
    assert 'closed before the end' in summary['exit_reason']
    assert summary['joint_state_rows'] == 37
    for key in SUMMARY_KEYS:
        assert key in summary, key
    feed(rec, state_msg(cell, 1.0, q[0], q[0]))  # after close: ignored, no error
    assert len(read_csv(rec.directory / 'timeseries.csv')[1]) == 37


def test_recorder_hears_the_graph(make_recorder, context, cell):
    """Messages published by another node of the same Context reach the CSV files."""
    rec = make_recorder('collaborative')
    probe = Node('probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(rec)
    executor.add_node(probe)
    states = probe.create_publisher(JointState, '/joint_states', 10)
    events = probe.create_publisher(DiagnosticStatus, '/conveyor/events', 10)

    def spin_until(predicate, timeout=20.0):
        import time
        end = time.monotonic() + timeout
        while time.monotonic() < end and not predicate():
            executor.spin_once(timeout_sec=0.01)
        return predicate()

    try:
        assert spin_until(lambda: states.get_subscription_count() > 0
                          and events.get_subscription_count() > 0)
        q = np.array([0.2, 1.2, 0.3])
        k = 0

        def publish_and_check():
            nonlocal k
            states.publish(state_msg(cell, 0.01 * k, q, mirror_joints(q)))
            k += 1
            return rec.log.t_last is not None and rec.log.t_last >= 0.05

        assert spin_until(publish_and_check)
        events.publish(event_msg('missed', 0.3, 4, cls='blue'))
        assert spin_until(lambda: len(rec.log.events) == 1)
        assert rec.log.events[0].kind == 'missed' and rec.log.events[0].cls == 'blue'
        summary = rec.finish('duration reached', False, plots=False)
        assert summary['joint_state_rows'] >= 6
    finally:
        executor.shutdown()
        probe.destroy_node()


def test_parse_value_and_run_log_windows(tmp_path, cell):
    """``parse_value`` reads booleans, numbers, NaN and text; event counts honour the window."""
    assert parse_value('true') is True and parse_value('False') is False
    assert parse_value('12') == 12 and parse_value('0.5') == 0.5
    assert parse_value('nan') is None and parse_value('') is None
    assert parse_value('collaborative') == 'collaborative'
    log = RunLog(tmp_path, cell)
    for t, kind in ((1.0, 'sorted'), (2.0, 'sorted'), (3.0, 'missed')):
        log.add_event(t, kind, 1)
    assert log.event_counts(1.5, 3.0)['sorted'] == 1
    log.close()
    assert math.isinf(log.min_distance)  # no states: no separation yet


def test_lost_joint_states_are_counted(make_recorder, cell):
    """Gaps in the state stamps are counted as missing states, with the largest gap."""
    rec = make_recorder('idle', batch=4)
    q = np.zeros(3)
    stamps = [0.0, 0.01, 0.02, 0.06, 0.07, 0.08, 0.09, 0.10, 0.30]  # 3 + 19 missing
    for t in stamps:
        feed(rec, state_msg(cell, t, q, q))
    summary = rec.finish('duration reached', False, plots=False)
    assert summary['joint_state_rows'] == len(stamps)
    assert summary['joint_states_missing'] == 22
    assert summary['largest_gap_s'] == pytest.approx(0.2)
    assert '22 of 31 joint states not heard' in report.format_report(summary)


def test_states_not_on_the_sim_clock_are_refused(make_recorder, cell):
    """A wall-clock stamp, an out-of-order one or NaN positions change nothing in the run."""
    rec = make_recorder('idle', batch=1)
    q = np.zeros(3)
    for k in range(5):
        feed(rec, state_msg(cell, 1.0 + 0.01 * k, q, q))
    rec.on_joint_state(state_msg(cell, 1.79e9, q, q))  # a rogue publisher's wall time
    rec.on_joint_state(state_msg(cell, 0.5, q, q))       # older than the last state
    rec.on_joint_state(state_msg(cell, 1.05, q + np.nan, q))
    assert rec.sim_time == pytest.approx(1.04)
    summary = rec.finish('duration reached', False, plots=False)
    assert summary['joint_state_rows'] == 5
    assert summary['joint_states_refused'] == 3
    assert summary['sim_time_end'] == pytest.approx(1.04)
    assert summary['joint_states_missing'] == 0


def stop_msg(kind, state, t, cause, since=None):
    """Return a stop event as the collision monitor publishes it."""
    return proto.StopEvent(kind, state, t, cause, since).to_msg()


def test_stop_events_become_the_summarys_stops(make_recorder, cell):
    """Stop events give each stop its time, cause, cost and whether it stands at the end.

    A stop standing at the end fails the run (exit 4), named on the report's first line; the
    latched /emergency_stop of the same stop does not count it twice.
    """
    rec = make_recorder('collaborative')
    q = np.array([0.0, 1.5708, 0.0])
    far = mirror_joints(q)
    feed(rec, state_msg(cell, 0.0, q, far))
    rec.start_job(0.0)
    rec.on_stop(stop_msg('protective', 'begin', 5.0, 'predicted breach in 0.21 s'))
    rec.on_stop(stop_msg('protective', 'end', 5.4, 'arms at rest 0.150 m apart', since=5.0))
    rec.on_stop(stop_msg('emergency', 'begin', 12.0, 'margin broken: ...'))
    bad = stop_msg('protective', 'begin', 13.0, 'x')
    bad.values = [kv for kv in bad.values if kv.key != 'time']
    rec.on_stop(bad)  # breaks the protocol: ignored with a warning
    feed(rec, state_msg(cell, 12.0, q, far))
    rec.on_estop(Bool(data=True))  # the same stop, latched for the bridge
    rec.on_monitor(proto.MonitorStatus(12.5, 0.2, 0.15, 3.0, 0.1, True, 'margin broken: ...',
                                       'emergency', 1, 1).to_msg())
    feed(rec, state_msg(cell, 20.0, q, far))
    summary = rec.finish('duration reached', False, plots=False)
    assert summary['protective_stops'] == [
        {'time': 5.0, 'cause': 'predicted breach in 0.21 s', 'lost': pytest.approx(0.4),
         'standing': False, 'end': 5.4, 'released': 'arms at rest 0.150 m apart',
         'source': 'stop event'}]
    (emergency,) = summary['emergency_stops']
    assert (emergency['time'], emergency['lost'], emergency['standing']) == (12.0, 8.0, True)
    assert summary['exit_code'] == 4 and summary['end_reason'] == 'duration reached'
    assert summary['exit_reason'] == ('emergency stop standing at the end of the run, since '
                                      'sim t=12.00 s: margin broken: ...')
    on_disk = json.loads((rec.directory / 'summary.json').read_text())
    assert on_disk['problems'] == [{'code': 4, 'text': summary['exit_reason']}]
    text = report.format_report(on_disk)
    assert text.splitlines()[0].startswith('scara_collab run: mode collaborative, FAILED, '
                                           'exit 4: emergency stop standing')
    assert 'stops          protective 1 (0.40 s lost), emergency 1 (8.00 s lost, STANDING' \
        in text


def test_an_emergency_stop_on_the_topic_alone_is_listed(make_recorder, cell):
    """Without stop events (a monitor that sends none), /emergency_stop's holds are the stops."""
    rec = make_recorder('idle')
    q = np.array([0.0, 1.5708, 0.0])
    for t, on in ((1.0, False), (3.0, True), (3.5, True), (4.25, False), (6.0, None)):
        feed(rec, state_msg(cell, t, q, mirror_joints(q)))
        if on is not None:
            rec.on_estop(Bool(data=on))
    summary = rec.finish('duration reached', False, plots=False)
    assert [(s['time'], s['lost'], s['standing'], s['source'])
            for s in summary['emergency_stops']] == [(3.0, 1.25, False, '/emergency_stop')]
    assert rec.estops == [3.0] and summary['protective_stops'] == []
    assert summary['exit_code'] == 0 and summary['problems'] == []


def spin_until(executor, predicate, timeout=15.0):
    """Spin ``executor`` until ``predicate()`` (wall ``timeout``); return it."""
    import time
    end = time.monotonic() + timeout
    while time.monotonic() < end and not predicate():
        executor.spin_once(timeout_sec=0.05)
    return predicate()


def test_a_second_clock_publisher_and_a_backward_clock_are_named(make_recorder, context):
    """A second /clock publisher is named (when, how many, who); a clock going back is counted.

    Either fails the run (exit 6), whatever else it did.
    """
    rec = make_recorder('idle')
    nodes = [Node(name, context=context) for name in ('clock_a', 'clock_b')]
    executor = SingleThreadedExecutor(context=context)
    for node in [rec] + nodes:
        executor.add_node(node)
    try:
        pubs = [n.create_publisher(Clock, '/clock', 10) for n in nodes]
        assert spin_until(executor, lambda: rec.graph_watch.foreign_clocks)
        (seen,) = rec.graph_watch.foreign_clocks
        assert seen['publishers'] == 2 and seen['nodes'] == ['/clock_a', '/clock_b']
        for t in (5.0, 2.0):
            pubs[0].publish(Clock(clock=conv.to_time(t)))
            assert spin_until(executor, lambda: rec.sim_time == t)
        assert rec.graph_watch.jumps == [{'time': 5.0, 'to': 2.0}]
        summary = rec.finish('duration reached', False, plots=False)
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
    assert summary['exit_code'] == 6, summary['problems']
    assert summary['exit_reason'].startswith('a second /clock publisher at sim t=')
    assert summary['exit_reason'].endswith('2 publishers (/clock_a, /clock_b)')
    assert [p['code'] for p in summary['problems']] == [6, 6]
    assert summary['clock_jumps_back_count'] == 1 and summary['graph_looks'] >= 1


def test_a_second_graph_on_the_domain_is_named(make_recorder, context):
    """Nodes of the run's names seen twice (another launcher's) are a second graph: exit 6."""
    import rclpy
    rec = make_recorder('idle')
    other = rclpy.Context()
    rclpy.init(context=other)
    twins = [Node('pybullet_bridge', context=context),
             Node('pybullet_bridge', context=other), Node('run_recorder', context=other)]
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(rec)
    try:
        both = {'/pybullet_bridge', '/run_recorder'}
        assert spin_until(executor, lambda: rec.graph_watch.second_graphs and set(
            rec.graph_watch.second_graphs[-1]['nodes']) == both)
        summary = rec.finish('duration reached', False, plots=False)
    finally:
        executor.shutdown()
        for node in twins:
            node.destroy_node()
        rclpy.try_shutdown(context=other)
    assert summary['second_graphs'][-1]['nodes'] == {'/pybullet_bridge': 2, '/run_recorder': 2}
    assert summary['exit_code'] == 6
    assert summary['exit_reason'].startswith('a second graph on the domain at sim t=0.00 s: ')


def test_a_person_runs_topics_become_the_person_block(make_recorder, cell):
    """With ``person``: the truth, the monitor, the clocks and the job's count make the block.

    Without it the recorder subscribes none of the person's topics and the summary has no
    block.
    """
    left, right = cell.leader.name, cell.follower.name
    rec = make_recorder('collaborative', person='inlet')
    topics = {s.topic_name for s in rec.subscriptions}
    assert {'/person/truth', '/separation_monitor/status', f'/{left}/trajectory_clock',
            f'/{right}/trajectory_clock'} <= topics
    q = np.array([0.0, 1.5708, 0.0])
    feed(rec, state_msg(cell, 0.0, q, mirror_joints(q)))
    rec.start_job(0.0)
    full = {left: 1.0, right: 1.0}
    rec.on_separation(proto.SeparationStatus(0.0, full).to_msg())
    rec.on_truth(proto.PersonTruth(1.0, True, {left: 0.4, right: 2.0}, {left: 0.1, right: 1.0},
                                   {left: True, right: True}, {left: False}).to_msg())
    rec.on_separation(proto.SeparationStatus(
        1.0, {left: 0.0, right: 1.0}, {left: True}, {left: 'person 1 ...: protective stop'},
        {left: 0.5, right: 2.1}, {left: -0.6, right: 0.4}).to_msg())
    rec.on_clock(proto.TrajectoryClock(left, 1.5, 0.25, 0.0, 0.0, held_back=True).to_msg())
    rec.on_truth(proto.PersonTruth(1.5, True, {left: 0.0}, {left: -0.2}, {left: True},
                                   {left: True}).to_msg())
    rec.on_separation(proto.SeparationStatus(2.5, full).to_msg())
    rec.on_truth(proto.PersonTruth(3.0, False).to_msg())
    rec.on_stats(proto.JobStats('collaborative', True, 3.0, 0.0, missed_due_to_person=2).to_msg())
    rec.on_separation(DiagnosticStatus(name='separation_monitor', message='garbled'))  # ignored
    feed(rec, state_msg(cell, 4.0, q, mirror_joints(q)))
    summary = rec.finish('duration reached', False)
    block = summary['person']
    assert block['scenario'] == 'inlet' and block['intrusions'] == 1
    assert block['protective_stops'] == 1 and block['stop_seconds'] == pytest.approx(1.5)
    assert block['min_separation_m'] == 0.0 and block['min_ssm_margin_m'] == -0.2
    assert block['contacts_while_moving'] == 1 and block['missed_due_to_person'] == 2
    assert block['arms'][left]['lag_max_s'] == 0.25 and block['arms'][left]['held_back'] == 1
    assert summary['exit_code'] == 8 and summary['exit_reason'].startswith(
        'a person touched a moving arm: 1 contact(s), the first with scara_left at sim t=1.50 s')
    assert 'separation.png' in summary['plots']
    assert_png(rec.directory / 'separation.png')
    assert 'person         inlet: 1 intrusion(s)' in report.format_report(summary)
    plain = make_recorder('collaborative', sub='plain')
    assert not {'/person/truth', '/separation_monitor/status'} & {
        s.topic_name for s in plain.subscriptions}
    assert plain.person is None
