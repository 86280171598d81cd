"""The run's verdict: summaries -> exit code, reason, problems and the report's first line."""
from pathlib import Path
import re

import pytest

from scara_collab.records import report
from scara_collab.records.verdict import apply, EXIT_CODES, verdict

ROOT = Path(__file__).resolve().parents[1]
CLEAN = {'mode': 'collaborative', 'exit_code': 0, 'exit_reason': 'duration reached',
         'interrupted': False, 'min_separation_m': 0.131, 'min_separation_time': 40.2,
         'safety_margin_m': 0.1, 'protective_stops': [], 'emergency_stops': [],
         'silences': [], 'foreign_clocks': [], 'clock_jumps_back': [], 'second_graphs': [],
         'silence_limits': {'notice_s': 1.5, 'lockstep_timeout_s': 5.0}}


def stop(t, cause, lost, standing=False):
    """Return a stop as the summary lists it."""
    return {'time': t, 'cause': cause, 'lost': lost, 'standing': standing,
            'end': None if standing else t + lost, 'released': '', 'source': 'stop event'}


def silence(node, t, wall, lag=0.0, dropped=False, ended=True):
    """Return a silence as the summary lists it."""
    return {'node': node, 'sim_time': t, 'wall_s': wall, 'lag_s': lag, 'ended': ended,
            'dropped': dropped}


GHOST_CLOCK = {'time': 4.21, 'wall_s': 20.0, 'publishers': 2,
               'nodes': ['/pybullet_bridge', '/rogue_clock']}
# (name, changes to the clean summary, exit code, text the reason starts with)
TABLE = [
    ('clean', {}, 0, 'duration reached'),
    ('stops that ended and a short silence', {
        'protective_stops': [stop(12.3, 'predicted breach in 0.2 s', 0.4)],
        'emergency_stops': [stop(30.0, 'emergency stop requested on /emergency_stop', 2.5)],
        'silences': [silence('automation_manager', 22.0, 2.1)]}, 0, 'duration reached'),
    ('margin broken', {'min_separation_m': 0.081}, 3,
     'margin broken: minimum separation 0.081 m < 0.1 m at sim t=40.20 s'),
    ('margin exactly held', {'min_separation_m': 0.1}, 0, 'duration reached'),
    ('emergency stop standing', {'emergency_stops': [stop(50.0, 'margin broken', 130.0, True)]},
     4, 'emergency stop standing at the end of the run, since sim t=50.00 s: margin broken'),
    ('protective stop standing', {'protective_stops': [
        stop(10.0, 'x', 0.3), stop(170.0, 'no valid joint state for 0.200 s', 10.0, True)]},
     4, 'protective stop standing at the end of the run, since sim t=170.00 s'),
    ('silence the bridge did not wait for', {'silences': [
        silence('left_planner', 30.7, 6.1, lag=1.2, dropped=True)]}, 5,
     'node left_planner silent 6.1 s wall, 1.2 s sim behind, from sim t=30.70 s'),
    ('second /clock publisher', {'foreign_clocks': [GHOST_CLOCK]}, 6,
     'a second /clock publisher at sim t=4.21 s: 2 publishers (/pybullet_bridge, '
     '/rogue_clock)'),
    ('clock went backwards', {'clock_jumps_back': [{'time': 9.5, 'to': 0.5}],
                              'clock_jumps_back_count': 3}, 6,
     '/clock went backwards 3 time(s), first at sim t=9.500 s (to 0.500 s)'),
    ('second graph', {'second_graphs': [{'time': 0.0, 'wall_s': 3.0,
                                         'nodes': {'/pybullet_bridge': 2}}]}, 6,
     'a second graph on the domain at sim t=0.00 s: 2 nodes named /pybullet_bridge'),
    ('the cause before its consequences', {
        'min_separation_m': 0.05, 'foreign_clocks': [GHOST_CLOCK],
        'emergency_stops': [stop(50.0, 'margin broken', 130.0, True)]}, 6,
     'a second /clock publisher'),
    ('a person touched a moving arm', {'person': {
        'contacts_while_moving': 1, 'first_contact_while_moving': {'time': 61.0,
                                                                   'robot': 'scara_left'}}},
     8, 'a person touched a moving arm: 1 contact(s), the first with scara_left at sim '
     't=61.00 s'),
    ("a moving arm within the person's protective separation", {'person': {
        'min_ssm_margin_m': -0.004, 'min_ssm_margin_robot': 'scara_right',
        'min_ssm_margin_time': 12.0, 'contacts_while_moving': 0}}, 8,
     'protective separation broken: S - S_p -0.004 m < 0 for scara_right'),
    ('a scanner dead to the end', {'person': {'fault_at_end': 'scanner_a: no scan for 9.000 s',
                                              'fault_since': 231.0}}, 4,
     'protective stop standing at the end of the run, since sim t=231.00 s: separation '
     'monitor: scanner_a: no scan for 9.000 s'),
    ('the arms before the person', {'min_separation_m': 0.05, 'person': {
        'contacts_while_moving': 1}}, 3, 'margin broken'),
    ('a silence before the stop it left', {
        'silences': [silence('collision_monitor', 30.0, 7.0, dropped=True, ended=False)],
        'protective_stops': [stop(30.1, 'no valid joint state', 150.0, True)]}, 5,
     'node collision_monitor silent 7.0 s'),
]


@pytest.mark.parametrize('name,changes,code,reason', TABLE, ids=[t[0] for t in TABLE])
def test_a_summary_gives_its_exit_code_and_reason(name, changes, code, reason):
    """Each summary gives its code and reason, on the report's first line and in the summary."""
    summary = dict(CLEAN, **changes)
    result = verdict(summary)
    assert result.code == code, result
    assert result.reason.startswith(reason), result.reason
    assert [p['code'] for p in result.problems] == sorted(
        [p['code'] for p in result.problems], key=[6, 3, 8, 5, 4].index)
    apply(summary)
    assert summary['exit_code'] == code and summary['exit_reason'] == result.reason
    assert summary['end_reason'] == 'duration reached'
    first = report.format_report(summary).splitlines()[0]
    if code == 0:
        assert first == 'scara_collab run: mode collaborative, finished (duration reached)'
        assert summary['problems'] == []
    else:
        assert first.startswith(f'scara_collab run: mode collaborative, FAILED, exit {code}: '
                                f'{reason}'), first
        assert first.endswith('; finished (duration reached)')
        assert summary['problems'][0] == {'code': code, 'text': result.reason}


def test_the_launchers_own_code_comes_first():
    """A run that ended early keeps its code and reason; its other problems are listed too."""
    summary = dict(CLEAN, exit_code=130, exit_reason='SIGINT', interrupted=True,
                   min_separation_m=0.05)
    result = apply(summary)
    assert (result.code, result.reason) == (130, 'SIGINT')
    assert [p['code'] for p in summary['problems']] == [130, 3]
    text = report.format_report(summary)
    assert text.splitlines()[0] == 'scara_collab run: mode collaborative, interrupted (SIGINT), ' \
        'exit 130'
    assert re.search(r'problems +exit 130: SIGINT\n +exit 3: margin broken', text), text
    dead = dict(CLEAN, exit_code=1, interrupted=True,
                exit_reason='node collision_monitor exited with code -9 (SIGKILL)')
    assert verdict(dead).code == 1 and verdict(dead).reason.startswith('node collision_monitor')
    closed = dict(CLEAN, exit_code=None, interrupted=True,
                  exit_reason='recorder closed before the end of the run')
    assert verdict(closed).code == 1, 'interrupted is never clean'


def test_the_report_names_stops_silences_and_intruders_in_a_few_lines():
    """Stops, silences, foreign clocks: a line each (at most three), then a count."""
    summary = dict(CLEAN, protective_stops=[stop(10.0 + k, f'cause {k}', 0.5) for k in range(5)],
                   emergency_stops=[stop(90.0, 'margin broken', 90.0, True)],
                   silences=[silence('left_planner', 3.0, 1.9)],
                   foreign_clocks=[GHOST_CLOCK])
    apply(summary)
    lines = report.format_report(summary).splitlines()
    stops = [k for k, line in enumerate(lines) if line.startswith('  stops')]
    assert len(stops) == 1
    block = lines[stops[0]:stops[0] + 5]
    assert block[0] == ('  stops          protective 5 (2.50 s lost), emergency 1 (90.00 s lost, '
                        'STANDING at the end)')
    assert block[1] == '                 emergency  t=90.00 s, standing: margin broken'
    assert block[2] == '                 protective t=10.00 s, 0.50 s: cause 0'
    assert block[4] == '                 ... and 3 more stops (summary.json)'
    text = '\n'.join(lines)
    assert 'silences       left_planner 1.9 s wall / 0.0 s sim behind from sim t=3.00 s' in text
    assert 'foreign clock  sim t=4.21 s: 2 /clock publishers (/pybullet_bridge, ' \
        '/rogue_clock)' in text
    assert re.search(r'problems +exit 6: .*\n +exit 4: emergency stop standing', text), text


def test_the_report_names_a_joint_faster_than_its_limit():
    """An overspeed episode is one line with the count and the first; none, no line."""
    assert 'overspeed' not in report.format_report(dict(CLEAN))
    fast = [{'time': 114.14, 'robot': 'scara_right', 'joint': 2, 'speed': 2.95, 'limit': 2.0}]
    text = report.format_report(dict(CLEAN, overspeed=fast, overspeed_count=3))
    assert ('  overspeed      3 time(s) a joint ran faster than its limit allows (no admitted '
            'trajectory does): first scara_right joint 2 2.95 (limit 2) at sim t=114.14 s') in text


def test_every_exit_code_is_documented():
    """The verdict's docstring and the README name every exit code the verdict can give."""
    from scara_collab.records import verdict as module
    status = ' '.join(module.__doc__.split())
    readme = ' '.join((ROOT / 'README.md').read_text(encoding='utf-8').split())
    readme = readme[readme.index('The exit status tells the truth'):]
    for code in EXIT_CODES:
        assert re.search(rf'\b{code} [a-zA-Z]', status), code
        assert re.search(rf'\b{code} [a-zA-Z]', readme), code
