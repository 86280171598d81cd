"""What a run with a person records: the person block, its CSV files, its plot, report, verdict.

The figures of :mod:`scara_collab.records.person` are checked on synthetic sequences of the
monitor's statuses and the bridge's truth, each figure against what the sequence was built to
hold; no ROS.
"""
import csv
import json
import math

import pytest

from scara_collab.records import report
from scara_collab.records.person import PersonLog, SEPARATION, TRUTH
from scara_collab.records.record import RunRecord
from scara_collab.records.verdict import EXIT_PERSON, EXIT_STOP_STANDING, verdict

PNG = b'\x89PNG\r\n\x1a\n'
L, R = 'left', 'right'
INF = math.inf
DT = 0.1


def ticks(t0, t1):
    """Return the times ``t0, t0 + DT, ...`` below ``t1``, rounded to the tick."""
    return [round(t0 + k * DT, 6) for k in range(int(round((t1 - t0) / DT)))]


def status(t):
    """Return the monitor's decision at ``t``: ``{robot: [scale, stop, S, margin]}, fault``.

    - 0 to 0.3 s: the start-up (the contour not taught, then the first rise);
    - left: slowed 3.0 to 5.8 s (margin < 0 until 3.5 s, a stop 4.0 to 4.5 s);
    - right: a ghost 10.0 to 10.5 s (margin < 0 at 10.0 and 10.1 s), nobody in the cell;
    - 15.0 to 15.2 s a fault (both stopped), both slowed to 15.5 s.
    """
    arms = {L: [1.0, False, INF, INF], R: [1.0, False, INF, INF]}
    fault = ''
    if t < 0.2:
        fault = "the empty cell's contour is not taught"
        arms = {r: [0.0, True, INF, INF] for r in arms}
    elif t < 0.3:
        arms = {r: [0.3, False, INF, INF] for r in arms}
    if 3.0 <= t < 5.8:
        arms[L] = [0.5, False, 1.5, -0.2 if t < 3.55 else 0.3]
        if 4.0 <= t < 4.5:
            arms[L] = [0.0, True, 1.2, -0.5]
    if 10.0 <= t < 10.5:
        arms[R] = [0.6, False, 0.8, -0.1 if t < 10.15 else 0.2]
    if 15.0 <= t < 15.2:
        fault = 'scanner_a: no scan for 0.070 s'
        arms = {r: [0.0, True, INF, INF] for r in arms}
    elif 15.2 <= t < 15.5:
        arms = {r: [0.5, False, INF, INF] for r in arms}
    return arms, fault


def truth(t):
    """Return the bridge's truth at ``t``: ``present, {robot: (S, margin, moving, contact)}``.

    The person is in the cell 2 to 8 s and 12 to 13 s; the left arm moves 2 to 6.5 s, its
    least separation 0.9 m and margin 0.25 m at 4.0 s, touched while moving at 6.0 and 6.1 s;
    the right arm, at rest, is touched at 7.0 s and is 0.2 m from the person (not counted).
    """
    present = 2.0 <= t < 8.0 or 12.0 <= t < 13.0
    arms = {L: (INF, INF, False, False), R: (INF, INF, False, False)}
    if present:
        arms = {L: (2.0, 1.0, 2.0 <= t < 6.5, False), R: (3.0, 2.0, False, False)}
    if t == 4.0:
        arms[L] = (0.9, 0.25, True, False)
    if t in (6.0, 6.1):
        arms[L] = (0.0, -0.3, True, True)
    if t == 7.0:
        arms[R] = (0.2, -1.0, False, True)
    return present, arms


def feed(log, t_end=20.0):
    """Feed ``log`` the built run up to ``t_end``: truth then status at each tick."""
    for t in ticks(0.0, t_end):
        present, tr = truth(t)
        log.add_truth(t, present, {r: v[0] for r, v in tr.items()},
                      {r: v[1] for r, v in tr.items()}, {r: v[2] for r, v in tr.items()},
                      {r: v[3] for r, v in tr.items()})
        arms, fault = status(t)
        log.add_status(t, {r: v[0] for r, v in arms.items()}, {r: v[1] for r, v in arms.items()},
                       {r: v[2] for r, v in arms.items()}, {r: v[3] for r, v in arms.items()},
                       fault)


@pytest.fixture
def log(tmp_path):
    """Yield a person log of two arms in ``tmp_path``; closed afterwards."""
    made = PersonLog(tmp_path, 'middle', [L, R], batch=7)
    yield made
    made.close()


def test_every_figure_of_the_person_block(log):
    """Each figure is what the built run holds (see :func:`status` and :func:`truth`)."""
    feed(log)
    log.add_stats(3)
    log.add_clock(L, 0.4, False)
    log.add_clock(L, 1.2, True)
    log.add_clock(L, 0.0, True)
    log.add_clock(L, 0.0, False)
    log.add_clock(L, 0.1, True)
    log.add_clock('other', 9.0, True)  # not an arm of the cell
    b = log.summary(20.0)
    assert b['scenario'] == 'middle'
    assert b['intrusions'] == 2 and b['present_seconds'] == pytest.approx(7.0)
    assert b['startup_seconds'] == pytest.approx(0.3)
    # left: its stop at 4.0 s; the fault stops both
    assert b['protective_stops'] == 3
    assert b['arms'][L]['protective_stops'] == 2 and b['arms'][R]['protective_stops'] == 1
    assert b['stop_seconds'] == pytest.approx(0.5 + 0.2)
    # any arm slowed: left 3.0-4.0 and 4.5-5.8, right 10.0-10.5, both 15.2-15.5
    assert b['slowed_seconds'] == pytest.approx(1.0 + 1.3 + 0.5 + 0.3)
    assert b['arms'][L]['slowed_seconds'] == pytest.approx(1.0 + 1.3 + 0.3)
    assert b['arms'][R]['stop_seconds'] == pytest.approx(0.2)
    assert b['slowdowns'] == 4 and b['arms'][L]['slowdowns'] == 2
    assert b['false_slowdowns'] == 1 and b['arms'][R]['false_slowdowns'] == 1
    # left: held (margin < 0, stop) until 4.4 s, clear 4.5 s, full 5.8 s; the ghost 10.2 to
    # 10.5 s; the fault 15.2 to 15.5 s
    assert b['resume_seconds_max'] == pytest.approx(1.3)
    assert b['arms'][R]['resume_seconds_max'] == pytest.approx(0.3)
    assert b['min_separation_m'] == 0.0 and b['min_separation_robot'] == L
    assert b['min_separation_time'] == pytest.approx(6.0)
    assert b['min_ssm_margin_m'] == -0.3 and b['min_ssm_margin_time'] == pytest.approx(6.0)
    assert b['arms'][R]['min_separation_m'] is None  # never moved
    assert b['contacts_while_moving'] == 1 and b['contacts'] == 2
    assert b['first_contact_while_moving'] == {'time': 6.0, 'robot': L}
    assert b['missed_due_to_person'] == 3
    assert b['fault_stops'] == 1 and b['fault_at_end'] == '' and b['fault_since'] is None
    assert b['faults'] == [{'time': 15.0, 'fault': 'scanner_a: no scan for 0.070 s',
                            'end': 15.2}]
    assert b['arms'][L]['lag_max_s'] == 1.2 and b['arms'][L]['held_back'] == 2
    assert b['truth_messages'] == 200 and b['monitor_statuses'] == 200
    json.dumps(b)


def test_the_least_separation_counts_only_a_moving_arm(log):
    """Without the contact, the least separation and margin are the left arm's at 4.0 s."""
    for t in ticks(0.0, 6.0):
        present, tr = truth(t)
        log.add_truth(t, present, {r: v[0] for r, v in tr.items()},
                      {r: v[1] for r, v in tr.items()}, {r: v[2] for r, v in tr.items()}, {})
    log.add_truth(7.0, True, {R: 0.05}, {R: -2.0}, {R: False}, {R: True})
    b = log.summary(8.0)
    assert (b['min_separation_m'], b['min_ssm_margin_m']) == (0.9, 0.25)
    assert b['min_separation_time'] == 4.0 and b['contacts_while_moving'] == 0
    assert b['contacts'] == 1
    assert b['protective_stops'] == 0 and b['startup_seconds'] is None  # no monitor heard


def test_a_fault_standing_at_the_end_is_named_and_counted_to_the_end(log):
    """A scanner silent from 5 s to the end: a stop of each arm, its time to the end."""
    log.add_status(0.0, {L: 1.0, R: 1.0}, {}, {}, {})
    for t in ticks(5.0, 6.0):
        log.add_status(t, {L: 0.0, R: 0.0}, {L: True, R: True}, {}, {},
                       f'scanner_b: no scan for {t - 4.96:.3f} s')
    b = log.summary(30.0)
    assert b['protective_stops'] == 2 and b['fault_stops'] == 1
    assert b['stop_seconds'] == pytest.approx(25.0)
    assert b['arms'][L]['stop_seconds'] == pytest.approx(25.0)
    assert b['fault_at_end'] == 'scanner_b: no scan for 0.940 s' and b['fault_since'] == 5.0
    assert b['faults'][0]['end'] is None and b['resume_seconds_max'] is None
    assert b['false_slowdowns'] is None  # no truth heard: nothing to tell a ghost by
    result = verdict({'exit_code': 0, 'exit_reason': 'duration reached', 'person': b})
    assert result.code == EXIT_STOP_STANDING
    assert result.reason == ('protective stop standing at the end of the run, since sim '
                             't=5.00 s: separation monitor: scanner_b: no scan for 0.940 s')


def test_the_start_up_ends_where_a_person_lowers_a_factor(log, tmp_path):
    """A factor that falls during the first rise ends the start-up: that slow-down counts."""
    log.add_status(0.0, {L: 0.0, R: 0.0}, {L: True, R: True}, {}, {}, 'scanner_a: no scan yet')
    log.add_status(0.5, {L: 0.2, R: 0.2}, {}, {}, {})
    log.add_status(0.6, {L: 0.3, R: 0.1}, {}, {R: 1.0}, {R: -0.4})  # right falls: a person
    log.add_status(1.0, {L: 1.0, R: 1.0}, {}, {}, {})
    b = log.summary(2.0)
    assert b['startup_seconds'] == pytest.approx(0.6)
    assert b['slowdowns'] == 2 and b['protective_stops'] == 0
    assert b['slowed_seconds'] == pytest.approx(0.4)
    assert b['arms'][R]['resume_seconds_max'] == pytest.approx(0.0)  # clear at full speed
    # a person standing inside S_p at standstill during the rise ends it too
    (tmp_path / 'again').mkdir()
    again = PersonLog(tmp_path / 'again', 'inlet', [L])
    again.add_status(0.0, {L: 0.0}, {L: True}, {}, {}, 'scanner_a: no scan yet')
    again.add_status(0.5, {L: 0.0}, {L: True}, {L: 1.0}, {L: -0.5})
    assert again.summary(1.0)['protective_stops'] == 1
    again.close()


def test_a_status_older_than_the_last_is_ignored(log):
    """Statuses out of order do not count twice nor back in time."""
    log.add_status(0.0, {L: 1.0, R: 1.0}, {}, {}, {})
    log.add_status(1.0, {L: 0.5, R: 1.0}, {}, {}, {})
    log.add_status(0.5, {L: 0.0, R: 0.0}, {L: True, R: True}, {}, {})
    b = log.summary(2.0)
    assert b['protective_stops'] == 0 and b['monitor_statuses'] == 2
    assert b['slowed_seconds'] == pytest.approx(1.0)


def test_the_csv_files_keep_s_s_p_and_the_scale(log):
    """``separation.csv``: S, S_p = S - margin, scale, stopped; ``person_truth.csv``: truth."""
    feed(log, 5.0)
    log.flush()
    with open(log.directory / SEPARATION, newline='') as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 50
    assert list(rows[0]) == ['t', 'fault', 'left_S_m', 'left_Sp_m', 'left_scale',
                             'left_stopped', 'right_S_m', 'right_Sp_m', 'right_scale',
                             'right_stopped']
    at = {float(r['t']): r for r in rows}
    assert at[3.0]['left_S_m'] == '1.500000' and float(at[3.0]['left_Sp_m']) == 1.7
    assert float(at[4.0]['left_Sp_m']) == 1.7 and at[4.0]['left_stopped'] == '1'
    assert at[3.0]['left_scale'] == '0.500000' and at[3.0]['right_Sp_m'] == 'inf'
    assert at[0.0]['fault'] == "the empty cell's contour is not taught"
    with open(log.directory / TRUTH, newline='') as f:
        truth_rows = list(csv.DictReader(f))
    assert len(truth_rows) == 50 and truth_rows[40]['present'] == '1'
    assert float(truth_rows[40]['left_S_m']) == 0.9 and truth_rows[40]['left_moving'] == '1'


def test_the_plot_and_the_report_lines(log, tmp_path):
    """``separation.png`` is drawn from the CSV files; the report has the person lines."""
    feed(log)
    log.add_stats(3)
    log.flush()
    path = report.plot_separation(tmp_path, tmp_path / 'separation.png', 0.0)
    data = path.read_bytes()
    assert data.startswith(PNG) and len(data) > 5000
    summary = {'mode': 'collaborative', 'exit_code': 0, 'exit_reason': 'duration reached',
               'person': log.summary(20.0)}
    text = report.format_report(summary)
    assert ('  person         middle: 2 intrusion(s), 3 protective stop(s) (0.70 s), slowed '
            '3.10 s, 4 slow-down(s) (1 false), full speed 1.30 s at most after clear of S_p'
            ) in text
    assert ('                 while moving: min separation 0.000 m, min S - S_p -0.300 m, '
            '1 contact(s); 3 missed for the person') in text
    assert ('                 separation monitor faults 1, first at t=15.00 s: scanner_a: no '
            'scan for 0.070 s') in text
    assert 'person' not in report.format_report(dict(summary, person=None))


def test_a_person_touching_a_moving_arm_or_inside_its_s_p_fails_the_run(log):
    """Exit 8 for a contact with a moving arm and for a broken protective separation."""
    clean = {'exit_code': 0, 'exit_reason': 'duration reached', 'min_separation_m': 0.2,
             'safety_margin_m': 0.1}
    block = {'contacts_while_moving': 0, 'min_ssm_margin_m': 0.05, 'fault_at_end': ''}
    assert verdict(dict(clean, person=block)).code == 0
    touched = dict(block, contacts_while_moving=2,
                   first_contact_while_moving={'time': 6.0, 'robot': 'scara_left'})
    result = verdict(dict(clean, person=touched))
    assert result.code == EXIT_PERSON == 8
    assert result.reason == ('a person touched a moving arm: 2 contact(s), the first with '
                             'scara_left at sim t=6.00 s')
    inside = dict(block, min_ssm_margin_m=-0.012, min_ssm_margin_robot='scara_right',
                  min_ssm_margin_time=33.5)
    result = verdict(dict(clean, person=inside))
    assert result.code == EXIT_PERSON
    assert result.reason == ('protective separation broken: S - S_p -0.012 m < 0 for '
                             'scara_right while it moved, at sim t=33.50 s (ground truth)')
    both = verdict(dict(clean, min_separation_m=0.05, person=dict(
        touched, fault_at_end='scanner_a: no scan yet', fault_since=0.0)))
    assert [p['code'] for p in both.problems] == [3, 8, 4]
    feed(log)
    assert verdict(dict(clean, person=log.summary(20.0))).code == EXIT_PERSON


def test_a_record_with_a_person_writes_its_block_and_files_and_one_without_none(tmp_path):
    """With a scenario: the block, both CSV files, the plot; without: none of them."""
    with_person = RunRecord(tmp_path / 'p', 'collaborative', person='middle')
    arms = [a.name for a in with_person.cell.arms]
    with_person.add_state(0.0, [0.0, 1.57, 0.0], [0.0, -1.57, 0.0])
    with_person.start_job(0.0)
    with_person.person.add_status(0.0, {a: 1.0 for a in arms}, {}, {}, {})
    with_person.person.add_truth(1.0, True, {arms[0]: 2.0}, {arms[0]: 0.5}, {arms[0]: True}, {})
    with_person.person.add_status(1.0, {arms[0]: 0.5, arms[1]: 1.0}, {}, {arms[0]: 2.0},
                                  {arms[0]: -0.1})
    with_person.add_state(2.0, [0.0, 1.57, 0.0], [0.0, -1.57, 0.0])
    summary = with_person.finish('duration reached', False)
    assert summary['person']['scenario'] == 'middle'
    assert summary['person']['slowed_seconds'] == pytest.approx(1.0)
    assert summary['person']['min_ssm_margin_m'] == 0.5 and summary['exit_code'] == 0
    assert 'separation.png' in summary['plots']
    for name in (SEPARATION, TRUTH, 'separation.png'):
        assert (tmp_path / 'p' / name).stat().st_size > 0
    on_disk = report.read_summary(tmp_path / 'p')
    assert on_disk['person']['intrusions'] == 1
    without = RunRecord(tmp_path / 'n', 'collaborative')
    without.add_state(0.0, [0.0, 1.57, 0.0], [0.0, -1.57, 0.0])
    summary = without.finish('duration reached', False)
    assert without.person is None and 'person' not in summary
    assert 'separation.png' not in summary['plots']
    assert sorted(p.name for p in (tmp_path / 'n').iterdir()) == [
        'arm_distance.png', 'events.csv', 'item_counts.png', 'summary.json',
        'timeseries.csv', 'tool_paths.png']
