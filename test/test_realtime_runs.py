"""The real-time benchmark's bookkeeping: its rows, its faults, its page (no launcher run)."""
from benchmarks import realtime_runs
from benchmarks.launched import row
from benchmarks.util import REALTIME_PAGE
from scara_collab.run.faults import parse_faults


def _summary(**over):
    s = {'exit_code': 0, 'sorted': 60, 'missed': 0, 'dropped': 0, 'min_separation_m': 0.131,
         'items_per_minute': 30.0, 'job': {'give_ups': 1},
         'protective_stops': [
             {'time': 40.0, 'cause': 'predicted: the commanded moves (...) bring ...',
              'lost': 0.6, 'standing': False},
             {'time': 70.0, 'cause': 'no valid joint state for 0.21 s (sim)', 'lost': 0.5,
              'standing': False}],
         'emergency_stops': [], 'cpu_per_sim_s': {'total': 1.279, 'pybullet_bridge': 0.477},
         'overspeed_count': 2}
    s.update(over)
    return s


def test_a_row_counts_the_stops_and_those_the_jobs_own_moves_caused():
    """Stops are counted by kind; the predicted ones are the job's own moves'."""
    r = row(_summary())
    assert (r['protective'], r['emergency'], r['own_moves']) == (2, 0, 1)
    assert r['lost_s'] == 1.1 and r['give_ups'] == 1
    assert 'no valid joint state' in r['causes']
    bare = row(_summary(protective_stops=None, emergency_stops=3))
    assert (bare['protective'], bare['emergency'], bare['own_moves']) == (0, 0, 0)
    assert (r['cpu_s'], r['overspeed']) == (1.279, 2)
    assert row({'exit_code': 1})['cpu_s'] is None  # a run that never got going


def test_every_condition_is_a_launcher_setting_that_parses():
    """Each condition is a valid launcher setting; lockstep is on only for the reference.

    The latency condition's faults are valid ``--fault`` entries for the joint states and
    every status the job's timing hangs on.
    """
    lockstep, hogs, faults = realtime_runs.CONDITIONS['latency']
    assert not lockstep and hogs == 0
    parsed = parse_faults(faults)
    assert set(parsed) == {'/joint_states', '/scara_left/planner_status',
                           '/scara_right/planner_status', '/scara_left/execution_status',
                           '/scara_right/execution_status'}
    assert [c for c, (on, _, _) in realtime_runs.CONDITIONS.items() if on] == ['lockstep']
    assert realtime_runs.CONDITIONS['two_hogs'][1] == 2


def test_the_page_has_a_row_per_run_and_the_capacity_ratio():
    """The Markdown page: one table row per run, the causes, the capacity line."""
    rows = [dict(row(_summary()), condition=c, seed=1)
            for c in ('lockstep', 'quiet')]
    cap = {'feed_interval': 0.9, 'duration': 240.0, 'seeds': [1],
           'lockstep_items_per_minute': 41.0, 'realtime_items_per_minute': 40.0,
           'ratio': 0.976}
    text = realtime_runs.markdown(rows, cap, 'scripts/bench_realtime.py --seeds 1', 600.0)
    assert text.count('| lockstep | 1 | 0 | 60 |') == 1 and '| quiet | 1 |' in text
    assert '| 1.100 | 2 | 1.279 |' in text  # lost_s, overspeed, cpu_s
    assert 'ratio 0.976' in text and 'Stop causes' in text


def test_a_rerun_replaces_its_block_and_keeps_the_notes_written_by_hand(tmp_path, monkeypatch):
    """``--only realtime`` writes its block; the page's other block and notes stay."""
    from argparse import Namespace
    page = tmp_path / REALTIME_PAGE
    page.write_text('# Real time, without lockstep\n\n## One process, at 1×\n\n'
                    '<!-- realtime:one_process:begin -->\nold\n'
                    '<!-- realtime:one_process:end -->\n\nnotes by hand\n\n'
                    '## One process per node, at 1×\n\n<!-- realtime:processes:begin -->\n'
                    'kept\n<!-- realtime:processes:end -->\n')
    monkeypatch.setattr(realtime_runs, 'run', lambda c, runs, d, s, log, one_process: dict(
        row(_summary(protective_stops=[])), condition=c, seed=s))
    args = Namespace(duration=60.0, seeds=[1], conditions=['quiet'], capacity_duration=0,
                     one_process=True)
    assert realtime_runs.section(args, page, 'cmd', lambda text: None) is True
    text = page.read_text()
    assert 'old' not in text and '| quiet | 1 | 0 | 60 |' in text
    assert 'notes by hand' in text and 'kept' in text and text.count('realtime:') == 4
