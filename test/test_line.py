"""A line of cells: sections, handoffs, the frontier, and a two-cell line end to end.

The core rules (:mod:`scara_collab.core.line`) without ROS; two PyBullet sections handing items
on; the line's accounting (:mod:`scara_collab.records.line_report`); then
``launch_cell.py --cells 2`` with handoff messages lost and repeated.
"""
import json
import math
import os
from pathlib import Path
import random
import subprocess
import sys

from diagnostic_msgs.msg import KeyValue
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.line import (arm_extent, HandedOn, Handoff, Inbox, min_pitch, OnBelt,
                                    Section, Share)
from scara_collab.core.model import load_cell
from scara_collab.nodes import protocol as proto
from scara_collab.records import line_report as lr
from scara_collab.run.line_launcher import cell_argv

ROOT = Path(__file__).resolve().parents[1]
CELL = load_cell()


def test_the_pitch_keeps_neighbouring_arms_a_margin_apart():
    """At the least pitch, arms of neighbours at full reach are the safety margin apart."""
    lo, hi = arm_extent(CELL)
    arm = CELL.arms[0]
    reach = arm.l1 + arm.l2 + arm.link_radius
    assert lo == pytest.approx(arm.base[0, 3] - reach) and hi == pytest.approx(
        arm.base[0, 3] + reach)
    pitch = min_pitch(CELL)
    assert pitch == pytest.approx(5.2)  # the figure for today's links and capsules
    assert (lo + pitch) - hi == pytest.approx(CELL.safety_margin)
    s = Section(CELL)
    assert s.transit == pytest.approx((pitch - 5.0) / CELL.belt.speed)
    assert Section(CELL, 6.0).transit == pytest.approx(1.0 / CELL.belt.speed)
    with pytest.raises(ValueError, match='below 5.200'):
        Section(CELL, 5.1)
    with pytest.raises(ValueError):
        Section(CELL, float('nan'))


def test_the_inbox_takes_each_item_once_and_never_moves_its_limit_back():
    """Repeats change nothing, a late frontier keeps the limit, a lost item is counted."""
    box = Inbox(Section(CELL))
    assert box.limit() == -math.inf  # nothing heard: no step
    h1, h2 = Handoff(1, 'red', 0.1, 3.0), Handoff(2, 'blue', -0.2, 3.5)
    got = box.offer(4.0, [h2, h1], handed=2)
    assert [h.item for h, _ in got] == [1, 2]  # in arrival order
    assert got[0][1] == pytest.approx(3.0 + box.section.transit)
    assert box.offer(4.02, [h1, h2], handed=2) == [] and box.repeats == 2
    assert box.offer(3.5, [], handed=2) == [] and box.limit() == pytest.approx(
        4.02 + box.section.transit)  # a late message: the limit stays
    box.offer(6.0, [], handed=3)  # upstream handed on a third, never heard here
    assert box.lost == 1 and box.received == 2


def test_handoffs_survive_lost_and_repeated_messages():
    """2,000 items through a channel losing 30 % and repeating 30 %: each arrives once, on time.

    The downstream cell steps only to the limit its inbox allows; no item may arrive before
    the time it has already reached (it would have passed it).
    """
    rng = random.Random(4)
    section = Section(CELL)
    out, box = HandedOn(window=2.0), Inbox(section)
    t, downstream, item = 0.0, 0.0, 0
    arrivals = {}
    while item < 2000:
        t = round(t + 0.02, 6)  # a message per clock
        while rng.random() < 0.06 and item < 2000:
            item += 1
            out.add(Handoff(item, rng.choice(('red', 'blue')), rng.uniform(-0.4, 0.4),
                            t - rng.uniform(0.0, 0.02)))
        sends = [] if rng.random() < 0.3 else [out.message(t)] * (2 if rng.random() < 0.3 else 1)
        for hs in sends:
            for h, at in box.offer(t, hs, out.handed):
                assert at >= downstream - 1e-9, f'item {h.item} arrives in the past'
                assert h.item not in arrivals
                arrivals[h.item] = at
        downstream = max(downstream, min(box.limit(), t))
    box.offer(t + 1.0, out.message(t + 1.0), out.handed)  # the last one gets through
    assert sorted(arrivals) == list(range(1, 2001))
    assert box.lost == 0 and box.repeats > 0


def test_handoff_records_are_checked_at_the_door():
    """A malformed handoff message is refused with a ProtocolError, a bad record with a reason."""
    msg = proto.LineHandoff(0, 2.5, 1, (Handoff(3, 'red', 0.1, 2.4),),
                            (OnBelt(4, 'blue', 1.0, 0.2),)).to_msg()
    back = proto.LineHandoff.from_msg(msg)
    assert back.handoffs == (Handoff(3, 'red', 0.1, 2.4),)
    assert back.belt == (OnBelt(4, 'blue', 1.0, 0.2),)
    for key, text in (('handoffs.3.y', 'nan'), ('handoffs.3.time', 'inf'), ('handoffs.3.y', 'y'),
                      ('handoffs.3.cls', ''), ('belt.4.x', '-inf'), ('frontier', 'inf'),
                      ('handed', '-1'), ('cell', '0.5')):
        bad = proto.LineHandoff(0, 2.5, 1, (Handoff(3, 'red', 0.1, 2.4),),
                                (OnBelt(4, 'blue', 1.0, 0.2),)).to_msg()
        next(kv for kv in bad.values if kv.key == key).value = text
        with pytest.raises(proto.ProtocolError, match=key.split('.')[-1]):
            proto.LineHandoff.from_msg(bad)
    for items in ([('handoffs.-3.cls', 'red'), ('handoffs.-3.y', '0.1'),
                   ('handoffs.-3.time', '2.4')],  # a negative id
                  [('handoffs.3.cls', 'red'), ('handoffs.3.y', '0.1')]):  # no time
        bad = proto.LineHandoff(0, 2.5, 1).to_msg()
        bad.values += [KeyValue(key=k, value=v) for k, v in items]
        with pytest.raises(proto.ProtocolError):
            proto.LineHandoff.from_msg(bad)
    for bad in ((Handoff(-1, 'red', 0.0, 1.0),), (Handoff(3, '', 0.0, 1.0),),
                (Handoff(3, 'red', float('nan'), 1.0),)):
        with pytest.raises(ValueError):
            proto.LineHandoff(0, 2.5, 1, bad)


def test_two_sections_hand_items_on_with_id_class_and_place():
    """Two PyBullet sections: items cross with their id, class and y, one transit later."""
    from scara_collab.sim.cell_sim import CellSim
    sim_cfg, ctl = load_config('simulation'), load_config('controllers')
    up = CellSim(CELL, dict(sim_cfg, feed_interval=0.0), ctl)
    down = CellSim(CELL, dict(sim_cfg, feed_interval=0.0), ctl)
    try:
        up.conveyor.line.join(True, 1)
        down.conveyor.line.join(False, 1_000_001)
        section = Section(CELL)
        out, box = HandedOn(), Inbox(section)
        ids = [up.conveyor.spawn_item('red', 0.3, 4.2),
               up.conveyor.spawn_item('blue', -0.25, 4.35)]
        ev_up, ev_down = up.conveyor.pop_events(), down.conveyor.pop_events()
        crossing = {}
        while up.time < 4.0:
            up.step(10)
            for h in up.conveyor.line.pop_handoffs():
                out.add(h)
                crossing[h.item] = h.time
            for h, at in box.offer(up.time, out.message(up.time), out.handed):
                down.conveyor.line.receive(h, at)
            while down.time + 0.01 <= box.limit() + 1e-9:
                down.step(10)
            ev_up += up.conveyor.pop_events()
            ev_down += down.conveyor.pop_events()
        handed = {e.item: e for e in ev_up if e.kind == 'handed_on'}
        got = {e.item: e for e in ev_down if e.kind == 'received'}
        assert sorted(handed) == sorted(got) == sorted(ids)
        assert not [e for e in ev_up if e.kind == 'missed']
        assert crossing[ids[0]] == pytest.approx((4.5 - 4.2) / CELL.belt.speed, abs=0.011)
        for i in ids:
            assert got[i].time == pytest.approx(crossing[i] + section.transit, abs=0.011)
        items = {it.id: it for it in down.conveyor.items()}
        assert items[ids[0]].cls == 'red' and items[ids[0]].position[1] == pytest.approx(0.3)
        assert items[ids[1]].cls == 'blue'
        # the cell's own items never meet handed ids
        assert down.conveyor.spawn_item() == 1_000_001
        with pytest.raises(ValueError, match='already on this belt'):
            down.conveyor.line.receive(Handoff(ids[0], 'red', 0.0, 1.0), down.time)
        with pytest.raises(ValueError, match='unknown class'):
            down.conveyor.line.receive(Handoff(77, 'green', 0.0, 1.0), down.time)
        with pytest.raises(ValueError, match='off the belt'):
            down.conveyor.line.receive(Handoff(78, 'red', 0.51, 1.0), down.time)
        # pushed towards the edge upstream (a 3-cell benchmark run had one at y=-0.493): on
        # the belt while its centre is, so it is taken
        down.conveyor.line.receive(Handoff(79, 'red', -0.493, down.time), down.time)
        down.step(10)
        assert {e.item for e in down.conveyor.pop_events() if e.kind == 'received'} == {79}
    finally:
        up.close()
        down.close()


def test_the_line_accounting_finds_lost_duplicated_and_foreign_items():
    """The line check names an item never received, a foreign one and a changed class."""
    ev = {0: [('5.0', 'handed_on', '1', 'red'), ('19.5', 'handed_on', '2', 'blue'),
              ('6.0', 'handed_on', '3', 'red')],
          1: [('6.0', 'received', '1', 'red'), ('7.0', 'received', '9', 'red'),
              ('7.0', 'received', '3', 'blue')]}
    check = lr.check_handoffs(ev, transit=1.0, end=20.0)
    assert check['in_transit'] == 1 and check['handoffs'] == 3  # item 2: still on its way
    assert check['problems'] == [
        'cell 1 received item 9, which cell 0 never handed on',
        'item 3 left cell 0 as red and came into cell 1 as blue']
    ev[1] = ev[1][:1]
    assert lr.check_handoffs(ev, 1.0, 20.0)['problems'] == [
        'item 3, handed on by cell 0 at t=6.00 s, never came into cell 1']


def test_each_cell_gets_the_lines_arguments_and_its_own_place():
    """A cell's launcher gets the line's arguments, its index, folder and stall timeout."""
    argv = ['--duration', '30', '--cells=3', '--output', 'x', '--quiet', '--seed', '4',
            '--stall-timeout', '9']
    assert cell_argv(argv, 2, 3, Path('/r'), 300.0) == [
        '--duration', '30', '--seed', '4', '--cells', '3', '--line-cell', '2', '--output',
        '/r/cell_2', '--quiet', '--stall-timeout', '300']


def test_a_two_cell_line_hands_items_on_through_lost_and_repeated_messages(tmp_path):
    """``launch_cell.py --cells 2``: cell 0 saturated, cell 1 sorts what it hands on.

    A third of the handoff messages are lost and a third repeated: every item handed on is
    received once, the items balance, the run exits 0 and says so per cell. Discovery goes
    through a Fast DDS discovery server (``--discovery-server``): every cell's nodes are its
    clients, the launchers its super clients.
    """
    out = tmp_path / 'line'
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    proc = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'launch_cell.py'), '--cells', '2',
         '--one-process', '--duration', '45', '--feed-interval', '0.5', '--rtf', '0',
         '--no-plots', '--output', str(out), '--fault', 'loss:/cell_0/line/handoff:0.3',
         '--fault', 'repeat:/cell_0/line/handoff:0.3', '--discovery-server'],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    server = proc.stdout.split('[launch] Fast DDS discovery server on ', 1)[1].split()[0]
    for k in (0, 1):
        assert json.loads((out / f'cell_{k}' / 'launch.json').read_text())[
            'ROS_DISCOVERY_SERVER'] == server
    s = json.loads((out / 'summary.json').read_text())
    assert [c['namespace'] for c in s['cells']] == ['/cell_0', '/cell_1']
    c0, c1 = s['cells']
    assert c0['handed_on'] > 0 and c1['received'] > 0 and c1['sorted'] > 0
    assert c0['handed_on'] == c1['received'] + s['between_cells']
    assert s['handoff_problems'] == [] and s['balanced']
    assert s['spawned'] == c0['spawned'] and c1['spawned'] == 0  # only cell 0 is fed
    assert 'line of 2 cells finished' in proc.stdout
    paces = [c['real_time_factor'] for c in s['cells']]
    assert all(p > 0 for p in paces) and s['real_time_factor'] == min(paces)
    assert f'{min(paces):.2f}x real time (its slowest cell)' in proc.stdout
    log = (out / 'cell_0' / 'logs').glob('*.log')
    assert any('fault injection: loss /cell_0/line/handoff' in p.read_text() for p in log)


def test_the_line_accounting_lets_a_dead_cells_section_carry_items_on():
    """Past a dead cell the next one takes what the dead section carried, not as a problem."""
    ev = {0: [('5.0', 'handed_on', '1', 'red'), ('30.0', 'handed_on', '2', 'blue')],
          1: [('6.0', 'received', '1', 'red')],
          2: [('60.0', 'received', '2', 'blue'), ('40.0', 'received', '1', 'red')]}
    check = lr.check_handoffs(ev, transit=1.0, end=80.0, died={1: 20.0})
    assert check['ok'], check['problems']
    assert check['through'] == 2 and check['into_dead'] == 1
    assert not lr.check_handoffs(ev, 1.0, 80.0)['ok']  # without the death: problems


def test_a_dead_cells_section_carries_its_items_to_the_next_cell(tmp_path):
    """``--cells 3`` with cell 1's bridge crashed mid-run (a killed process).

    Cell 2 takes cell 1 for dead once it stays silent, and sorts on: the items on cell 1's belt
    and the ones cell 0 hands on after ride through the dead section to it. Cell 0 never
    waits for anyone downstream. The line exits non-zero and its report names cell 1.
    """
    out = tmp_path / 'line'
    proc = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'launch_cell.py'), '--cells', '3',
         '--one-process', '--duration', '70', '--feed-interval', '0.5', '--rtf', '0',
         '--no-plots', '--output', str(out), '--fault', 'crash:/cell_1/pybullet_bridge:35'],
        cwd=ROOT, env=dict(os.environ), capture_output=True, text=True, timeout=900)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    s = json.loads((out / 'summary.json').read_text())
    c0, c1, c2 = s['cells']
    assert s['died'] == [1] and c1['died_at'] == pytest.approx(35.0, abs=0.05)
    assert c0['exit_code'] == 0 and c0['sim_seconds'] == pytest.approx(70.0)
    assert c2['exit_code'] == 0 and c2['sim_seconds'] == pytest.approx(70.0)
    assert s['through_dead'] > 0 and s['handoff_problems'] == []
    events = lr.read_events(out / 'cell_2')
    after = [float(t) for t, kind, _, _ in events if kind == 'sorted' and float(t) > 40.0]
    assert after, 'cell 2 sorted nothing after cell 1 died'
    assert 'cell 1 DIED at sim t=35.0 s' in proc.stdout
    log = (out / 'cell_2' / 'logs' / 'cell.log').read_text()
    assert 'taken for dead' in log and 'line: sorting again: item' in log  # the recovery, timed


def test_below_saturation_each_cell_takes_its_share_so_the_load_is_even():
    """Three cells at 30 items/min: each takes a third of the feed; saturated, all it can."""
    shares = [Share(k, 3, capacity=40.0) for k in range(3)]
    taken = [0, 0, 0]
    t = 0.0
    for item in range(1, 301):  # an item every 2 s, 10 sim min
        t += 2.0
        for k, share in enumerate(shares):
            share.see([item], t)
            if share.takes(item, t):
                taken[k] += 1
                break
    assert taken == [100, 100, 100] and not shares[0].saturated(t)
    last = Share(2, 3, capacity=40.0)
    last.see(range(50), 0.0)
    assert all(last.takes(i, 0.0) for i in range(50))  # the last cell never leaves one
    busy = Share(0, 3, capacity=40.0)  # 150 items/min reach it: a third is more than it can
    for i in range(300):
        busy.see([i], i * 0.4)
    assert busy.rate(120.0) == pytest.approx(150.0, rel=0.02) and busy.saturated(120.0)
    assert all(busy.takes(i, 120.0) for i in range(300))  # it takes what it can
    with pytest.raises(ValueError):
        Share(3, 3, 40.0)


def test_a_cells_place_in_the_line_is_checked_with_the_job_settings():
    """``line_cell`` must be a cell of ``line_cells``; a lone cell has no share."""
    from scara_collab.core.job import SortingJob
    from scara_collab.core.job_settings import JobSettings
    cfg = load_config('automation')
    with pytest.raises(ValueError, match='line_cell 2 is not a cell of a line of 2'):
        JobSettings.from_config(CELL, dict(cfg, line_cell=2, line_cells=2))
    lone = SortingJob(CELL, JobSettings.from_config(CELL, cfg), lambda *a: None)
    settings = JobSettings.from_config(CELL, dict(cfg, line_cell=0, line_cells=2))
    in_line = SortingJob(CELL, settings, lambda *a: None)
    assert lone.share is None and in_line.share.share == pytest.approx(0.5)


def test_the_line_benchmark_writes_each_scenario_into_its_own_block(tmp_path):
    """``--only line --scenarios ...``: a block per scenario; a rerun replaces only its own.

    The killed-cell scenario reads the recovery from the logs' wall stamps: the kill in cell
    1's log, the first sort after the takeover in cell 2's.
    """
    from benchmarks import line_scenarios as bench
    from benchmarks.util import LINE_PAGE, write_block
    page = tmp_path / LINE_PAGE
    page.write_text('# A line of cells\n\nkept by hand\n')
    rated = {'cells': 2, 'duration': 600.0, 'feed_interval': 0.9, 'missed': 0, 'dropped': 1,
             'handoffs': 301, 'handoff_problems': 0, 'balanced': True,
             'min_separation_m': [0.131, 0.142], 'exit_code': 0}
    killed = dict(rated, cells=3, at=300.0, cell0_identical=True, sorting_again_wall_s=7.25,
                  lookahead_s=1.0, named=True, died=[1], calm_exit=0, exit_code=1)
    write_block(page, 'line:rated', 'At N times the rated feed', bench.rated_text([rated], 'a'))
    write_block(page, 'line:kill', 'A killed cell', bench.kill_text(killed, 'b'))
    write_block(page, 'line:rated', 'At N times the rated feed',
                bench.rated_text([dict(rated, missed=2)], 'c'))
    text = page.read_text()
    assert 'kept by hand' in text and text.count('line:rated:begin') == 1
    assert '| 2 | 600.0 | 0.9 | 2 | 1 | 301 | 0 | True | 0.131, 0.142 | 0 |' in text
    assert '| True | 7.2 | 11.0 | True | [1] | 0, 1 |' in text and 'Measured with `b`' in text
    logs = tmp_path / 'cell.log'
    logs.write_text('[INFO] [1796198515.138241243] [x]: other\n'
                    '[WARN] [1796198520.500000000] [pybullet_bridge]: line: sorting again: ...\n')
    assert bench.wall_of(logs, 'line: sorting again') == pytest.approx(1796198520.5)
    paced = dict(rated, cells=3, duration=120.0, rtf=1.0, real_time_factor=[0.99, 0.96, None],
                 cpu_per_cell=[0.5, 0.4, 0.3], sorted=150)
    write_block(page, 'line:realtime', 'Real time', bench.realtime_text(
        [dict(paced, rtf=0.0, real_time_factor=[1.6, 1.5, 1.7]), paced], 'd'))
    text = page.read_text()
    assert '| 3 | unthrottled | 120 | 1.60, 1.50, 1.70 | 1.50 | 0.50, 0.40, 0.30 | 150 |' in text
    assert '| 3 | 1x | 120 | 0.99, 0.96, - | - |' in text  # a cell without a pace: none


def test_the_line_capacity_block_sets_each_cells_cpu_beside_one_cells():
    """The capacity block shows one cell's CPU beside the line's, and the worst ratio."""
    from benchmarks import line_scenarios as bench
    row = {'cells': 2, 'belt_speed': 0.4, 'feed_interval': 0.45, 'one_cell': 41.1,
           'items_per_minute': 79.3, 'ratio': 0.964, 'worst_cell_ratio': 0.948,
           'per_cell': [40.3, 39.0], 'min_separation_m': [0.142, 0.182],
           'cpu_per_cell': [0.98, 0.88], 'one_cell_cpu': 0.8, 'cpu_ratio': 1.225,
           'handoffs': 258, 'handoff_problems': 0, 'exit_code': 0}
    text = bench.capacity_text([row], 'cmd')
    assert '| CPU s per sim s per cell (one cell) | worst CPU / one (<= 1.1) |' in text
    assert '| 0.98, 0.88 (0.80) | 1.225 |' in text


def test_an_item_handed_on_close_behind_another_comes_on_behind_it_not_into_it():
    """Two items that cross closer than an item's size come on touching, none pushed off."""
    from scara_collab.sim.cell_sim import CellSim
    sim_cfg, ctl = load_config('simulation'), load_config('controllers')
    down = CellSim(CELL, dict(sim_cfg, feed_interval=0.0), ctl)
    try:
        down.conveyor.line.join(False, 1_000_001)
        size, speed = CELL.item_size, CELL.belt.speed
        close = 0.6 * size / speed  # s apart at the boundary: their centres 0.6 sizes apart
        down.conveyor.line.receive(Handoff(1, 'red', 0.05, 0.0), 0.0)
        down.conveyor.line.receive(Handoff(2, 'red', 0.0, close), close)
        down.step(int(round(3.0 / down.dt)))
        events = down.conveyor.pop_events()
        assert [(e.kind, e.item) for e in events] == [('received', 1), ('received', 2)]
        assert events[1].time > close  # it waited until the first had moved on
        items = {it.id: it for it in down.conveyor.items()}
        assert items[1].state == items[2].state == 'belt'
        gap = items[1].position[0] - items[2].position[0]
        assert size <= gap < size + 0.01  # touching, as they came, not one into the other
        assert abs(items[1].position[1] - 0.05) < 1e-3 and abs(items[2].position[1]) < 1e-3
    finally:
        down.close()
