"""The files of one run and their numbers, against figures computed here independently.

The tool tips come from a homogeneous-transform chain built here, the mirror error from the
joint-space reflection (``theta1, theta2 -> -theta1, -theta2``: no ``core.mirror``), the arm
distance from capsules built on that chain and a golden-section search of the point-to-segment
distance (no ``core.collision``).
"""
import math
import os
import time

import numpy as np
import pytest

from scara_collab.records.telemetry import (
    ARM_DISTANCE, COUNTED, CpuMeter, EVENT_COLUMNS, EVENTS, MIRROR_ERROR, parse_value,
    process_cpu_seconds, RunLog, state_columns, state_metrics, TIMESERIES)

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _shift(x: float = 0.0, z: float = 0.0) -> np.ndarray:
    out = np.eye(4)
    out[0, 3], out[2, 3] = x, z
    return out


def chain_points(arm, q):
    """Return shoulder, elbow, wrist (link 2's end) and tool tip in world, from 4x4 frames."""
    theta1, theta2, d3 = q
    shoulder = arm.base @ _shift(z=arm.shoulder_height) @ _rot_z(theta1)
    elbow = shoulder @ _shift(x=arm.l1)
    wrist = elbow @ _shift(z=arm.elbow_rise) @ _rot_z(theta2) @ _shift(x=arm.l2)
    tip = arm.base @ _rot_z(theta1) @ _shift(x=arm.l1) @ _rot_z(theta2) @ _shift(
        x=arm.l2, z=arm.tool_z0 - d3)
    return shoulder[:3, 3], elbow[:3, 3], wrist[:3, 3], tip[:3, 3]


def capsules(arm, q):
    """Return the arm's capsules ``[(start, end, radius)]``: link 1, link 2, the quill."""
    shoulder, elbow, wrist, tip = chain_points(arm, q)
    up = arm.base[:3, 2]
    return [(shoulder, elbow, arm.link_radius),
            (elbow + arm.elbow_rise * up, wrist, arm.link_radius),
            (tip, tip + arm.quill_length * up, arm.quill_radius)]


def point_to_segment(p, a, b) -> float:
    """Distance from point ``p`` to segment ``ab`` (projection clipped to the segment)."""
    ab = b - a
    u = min(max(float(np.dot(p - a, ab) / np.dot(ab, ab)), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + u * ab)))


def segment_gap(a0, a1, b0, b1) -> float:
    """Distance between two segments: golden-section search along the first (convex in s)."""
    lo, hi = 0.0, 1.0
    for _ in range(80):
        s1, s2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
        d1 = point_to_segment(a0 + s1 * (a1 - a0), b0, b1)
        d2 = point_to_segment(a0 + s2 * (a1 - a0), b0, b1)
        lo, hi = (lo, s2) if d1 <= d2 else (s1, hi)
    return point_to_segment(a0 + lo * (a1 - a0), b0, b1)


def expected_figures(cell, q_lead, q_foll):
    """Return (tool tips of both arms, mirror error, arm distance) of one state, computed here."""
    lead, foll = cell.leader, cell.follower
    p_lead, p_foll = chain_points(lead, q_lead)[3], chain_points(foll, q_foll)[3]
    mirrored = chain_points(foll, np.asarray(q_lead) * [-1.0, -1.0, 1.0])[3]
    distance = min(segment_gap(a0, a1, b0, b1) - ra - rb
                   for a0, a1, ra in capsules(lead, q_lead)
                   for b0, b1, rb in capsules(foll, q_foll))
    return p_lead, p_foll, float(np.linalg.norm(p_foll - mirrored)), distance


@pytest.fixture(scope='module')
def series(cell):
    """Return 40 states ``(t, q_lead, q_foll)``, the arms often close, and a gap of 4 states."""
    rng = np.random.default_rng(7)
    lower, upper = cell.leader.lower, cell.leader.upper
    q_lead = rng.uniform(lower * 0.8, upper * 0.8, size=(40, 3))
    q_foll = q_lead * [-1.0, -1.0, 1.0] + rng.normal(0.0, 0.3, size=(40, 3))  # near mirrored
    q_foll[:, 2] = np.clip(q_foll[:, 2], lower[2], upper[2])
    q_foll[5] = q_lead[5] * [-1.0, -1.0, 1.0]   # exactly mirrored: zero error
    t = 0.01 * np.arange(40)
    t[20:] += 0.04                              # four states never heard
    return t, q_lead, q_foll


def test_state_metrics_match_the_chain_the_reflection_and_the_capsules(cell, series):
    """Tool tips, mirror error and distance agree with the independent figures, one or many."""
    _, q_lead, q_foll = series
    p_lead, p_foll, error, distance = state_metrics(cell, q_lead, q_foll)
    assert p_lead.shape == p_foll.shape == (40, 3) and error.shape == distance.shape == (40,)
    want = [expected_figures(cell, a, b) for a, b in zip(q_lead, q_foll)]
    np.testing.assert_allclose(p_lead, [w[0] for w in want], atol=1e-9)
    np.testing.assert_allclose(p_foll, [w[1] for w in want], atol=1e-9)
    np.testing.assert_allclose(error, [w[2] for w in want], atol=1e-9)
    np.testing.assert_allclose(distance, [w[3] for w in want], atol=1e-7)
    assert error[5] < 1e-12 and np.any(distance < 0.3), 'the series has arms close together'
    one = state_metrics(cell, q_lead[3], q_foll[3])  # one state: no leading axis
    assert one[0].shape == (3,) and np.shape(one[2]) == np.shape(one[3]) == ()
    assert float(one[3]) == pytest.approx(distance[3], abs=1e-12)


def test_run_log_figures_and_rows_are_those_of_the_series(cell, series, tmp_path):
    """The run log's minimum, maximum, gaps and CSV rows are the series' own figures."""
    t, q_lead, q_foll = series
    log = RunLog(tmp_path, cell, batch=7, state_period=0.01)
    for k in range(40):
        log.add_state(t[k], q_lead[k], q_foll[k])
    log.close()
    log.add_state(9.0, q_lead[0], q_foll[0])  # after the close: ignored
    want = [expected_figures(cell, a, b) for a, b in zip(q_lead, q_foll)]
    error = np.array([w[2] for w in want])
    distance = np.array([w[3] for w in want])
    assert log.rows == 40 and (log.t_first, log.t_last) == (t[0], t[-1])
    assert log.min_distance == pytest.approx(distance.min(), abs=1e-7)
    assert log.min_distance_time == t[np.argmin(distance)]
    assert log.max_mirror_error == pytest.approx(error.max(), abs=1e-9)
    assert log.max_mirror_error_time == t[np.argmax(error)]
    assert log.missing == 4 and log.largest_gap == pytest.approx(0.05)
    header = (tmp_path / TIMESERIES).read_text().splitlines()[0].split(',')
    assert header == state_columns(cell)
    rows = np.loadtxt(tmp_path / TIMESERIES, delimiter=',', skiprows=1)
    col = {name: k for k, name in enumerate(header)}
    assert rows.shape == (40, len(header))
    np.testing.assert_allclose(rows[:, col['t']], t, atol=1e-4)
    tips = [col[f'{a.name}_tool_{axis}'] for a in cell.arms for axis in 'xyz']
    np.testing.assert_allclose(rows[:, tips], [np.hstack(w[:2]) for w in want], atol=1e-6)
    np.testing.assert_allclose(rows[:, col[MIRROR_ERROR]], error, atol=1e-9)
    np.testing.assert_allclose(rows[:, col[ARM_DISTANCE]], distance, atol=1e-6)


def test_events_are_written_at_once_and_counted_per_window(cell, tmp_path):
    """Each event is on disk when added; the counts honour the window and keep every kind."""
    log = RunLog(tmp_path, cell)
    for time_s, kind, item in ((1.0, 'spawned', 1), (2.0, 'grasped', 1), (3.0, 'sorted', 1),
                               (4.0, 'spawned', 2), (5.0, 'missed', 2)):
        log.add_event(time_s, kind, item, 'red', 'scara_left' if kind != 'missed' else '')
    lines = (tmp_path / EVENTS).read_text().splitlines()
    assert lines[0].split(',') == list(EVENT_COLUMNS) and len(lines) == 6
    assert lines[3] == '3.000,sorted,1,red,scara_left,'
    assert log.event_counts() == {'spawned': 2, 'received': 0, 'sorted': 1, 'missed': 1,
                                  'handed_on': 0, 'wrong_bin': 0, 'dropped': 0, 'grasped': 1}
    window = log.event_counts(2.0, 4.0)
    assert set(COUNTED) <= set(window) and (window['spawned'], window['sorted']) == (1, 1)
    log.close()
    assert math.isinf(log.min_distance) and log.rows == 0  # no states: no separation


def test_parse_value_reads_what_a_status_carries():
    """Numbers, booleans and the ways of writing "no value" become Python values."""
    assert parse_value(' 7 ') == 7 and parse_value('1e3') == 1000.0
    assert parse_value('TRUE') is True and parse_value('false') is False
    assert all(parse_value(v) is None for v in ('inf', '-inf', 'NaN', 'N/A', 'null', ' '))
    assert parse_value('scara_left/12') == 'scara_left/12'


def test_the_cpu_meter_gives_cpu_seconds_per_sim_second_per_process():
    """The CPU meter gives each process's CPU seconds per sim second, and their total."""
    own = process_cpu_seconds(os.getpid())
    assert own is not None and own > 0
    assert process_cpu_seconds(2 ** 22 + 7) is None  # no such process
    meter = CpuMeter()
    assert not meter.marked
    meter.mark({'a': 1.0, 'b': 10.0, 'gone': None}, sim_time=5.0)
    assert meter.marked
    assert meter.close({'a': 3.0, 'b': 11.0, 'gone': 4.0}, sim_time=15.0) == {
        'a': 0.2, 'b': 0.1, 'total': 0.3}
    meter.mark({'a': 1.0}, sim_time=5.0)
    assert meter.close({'a': 2.0}, sim_time=5.0) == {}  # no sim time passed: no figure


def test_process_cpu_seconds_agrees_with_the_process_own_account():
    """``/proc/<pid>/stat`` gives what ``os.times`` says this process used (clock ticks)."""
    end = time.process_time() + 0.2
    while time.process_time() < end:  # burn a little CPU so the figure is not all start-up
        pass
    before = os.times()
    proc = process_cpu_seconds(os.getpid())
    after = os.times()
    assert before.user + before.system - 0.02 <= proc <= after.user + after.system + 0.02


def test_a_joint_faster_than_its_limit_is_an_episode_named_once_with_its_peak(cell, tmp_path):
    """A joint that jumps: one episode per burst: its start, its peak; a gap is not a speed.

    The right elbow moves at its limit (not named), then 0.03 and 0.05 rad in two 10 ms
    steps (3 and 5 rad/s against 2: one episode, peak 5), then again 1 s later (a second
    episode); a 0.5 rad step across a 1 s gap in the states is no speed at all.
    """
    log = RunLog(tmp_path, cell, batch=3, state_period=0.01)
    q = np.zeros(6)
    t = 0.0
    steps = [0.02] * 5 + [0.03, 0.05] + [0.0] * 100 + [0.04]
    log.add_state(t, q[:3], q[3:])
    for dq in steps:
        t += 0.01
        q[4] += dq
        log.add_state(t, q[:3], q[3:])
    t += 1.0
    q[4] += 0.5  # after a gap in the states
    log.add_state(t, q[:3], q[3:])
    log.close()
    limit = float(cell.follower.max_velocity[1])
    assert log.overspeed_count == 2
    first, second = log.overspeed
    assert (first['robot'], first['joint'], first['limit']) == (cell.follower.name, 2, limit)
    assert first['time'] == pytest.approx(0.06) and first['speed'] == pytest.approx(5.0)
    assert second['time'] == pytest.approx(1.08) and second['speed'] == pytest.approx(4.0)
    assert log.max_speed_ratio == pytest.approx(5.0 / limit)
