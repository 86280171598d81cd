"""The bridge's execution core and its pacing, without a graph: refusals, the guard, the rate."""
import numpy as np
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from scara_collab.core.config import load_config
from scara_collab.nodes.execution import Execution, Holds
from scara_collab.nodes.pybullet_bridge import Pacer
from scara_collab.sim import CellSim


def _small_move(sim, robot, move='m1'):
    """Return a 0.5 s trajectory message that turns ``robot``'s first joint by 0.1 rad."""
    q0 = sim.arm_state(robot)[0]
    msg = JointTrajectory(joint_names=list(sim.cell.arm(robot).joint_names))
    msg.header.frame_id = move
    for k, t in enumerate((0.0, 0.5)):
        point = JointTrajectoryPoint(positions=(q0 + [0.1 * k, 0.0, 0.0]).tolist())
        point.time_from_start.sec, point.time_from_start.nanosec = 0, int(t * 1e9)
        msg.points.append(point)
    return msg


def test_no_move_starts_while_blocked_and_every_path_is_asked(cell):
    """While ``blocked`` gives a reason (a lockstep guard is missing) every move is refused.

    The topic and the action server both run moves through :meth:`Execution.run`, so neither
    can start an arm while the collision monitor is not watching.
    """
    reports, why = [], ['/collision_monitor stopped answering: no move until it answers again']
    cfg = dict(load_config('simulation'), feed_interval=0.0)
    with CellSim(cell, cfg) as sim:
        robot = cell.leader.name
        ex = Execution(cell, sim, lambda *a, **k: reports.append((a, k)), lambda text: None,
                       blocked=lambda: why[0])
        assert ex.run(robot, _small_move(sim, robot)) is None
        assert reports[-1][0][:3] == (robot, 'refused', 'm1') and reports[-1][0][3] == why[0]
        assert not sim.active(robot) and ex.reason == why[0]
        why[0] = ''
        span = ex.run(robot, _small_move(sim, robot, 'm2'))
        assert span is not None and sim.active(robot)
        assert reports[-1][0][:3] == (robot, 'accepted', 'm2')


def test_the_pacer_keeps_the_rate_and_says_when_its_tick_changes(monkeypatch):
    """Unthrottled: a chunk per tick. Throttled: the steps the wall clock has made due."""
    wall = [100.0]
    monkeypatch.setattr('scara_collab.nodes.pybullet_bridge.time.monotonic', lambda: wall[0])
    p = Pacer(0.0, 0.001, 10)
    assert p.period == 0.0 and p.due(5.0) == 10
    assert p.set_rate(2.0) and p.period == 0.002
    assert p.due(5.0) == 0  # counting starts now
    wall[0] += 0.004
    assert p.due(5.0) == 8  # 4 ms of wall time at 2x: 8 ms of sim time
    assert not p.set_rate(1.0)  # throttled to throttled: the same tick
    wall[0] += 1.0  # a new rate counts afresh from its first tick
    assert p.due(5.0) == 0
    wall[0] += 1.0  # the machine fell 1000 steps behind: one chunk, and count from here
    assert p.due(5.0) == 10 and p.due(5.01) == 0
    assert np.isclose(p.rtf, 1.0)


def test_a_stop_holds_both_arms_until_the_last_stop_ends_and_a_guard_blocks_moves(cell):
    """A stop drops both arms' moves till the last one ends; a missing guard blocks moves."""
    reports, absent = [], {}
    cfg = dict(load_config('simulation'), feed_interval=0.0)
    with CellSim(cell, cfg) as sim:
        ex = Execution(cell, sim, lambda *a, **k: reports.append(a), lambda text: None)
        holds = Holds(cell, sim, ex, lambda: absent, lambda text: None)
        ex.blocked = holds.blocked
        robot = cell.leader.name
        assert ex.run(robot, _small_move(sim, robot)) is not None
        holds.on_stop('protective', True)
        assert sim.estop and [r[:2] for r in reports[-2:]] == [(robot, 'held'),
                                                               (cell.follower.name, 'held')]
        assert reports[-2][2] == 'm1' and reports[-2][3] == 'protective stop: holding'
        n = len(reports)
        holds.on_stop('emergency', True)  # a second stop: nothing new to say
        holds.on_stop('protective', False)  # the emergency still stands
        assert sim.estop and len(reports) == n
        holds.on_stop('emergency', False)
        assert not sim.estop and [r[1] for r in reports[n:]] == ['cleared', 'cleared']
        absent['/collision_monitor'] = 'stopped answering'
        holds.on_guard('/collision_monitor', False, 'stopped answering')
        assert [r[1] for r in reports[-2:]] == ['held', 'held']
        assert holds.blocked().startswith('/collision_monitor stopped answering')
        assert ex.run(robot, _small_move(sim, robot, 'm2')) is None
        del absent['/collision_monitor']
        holds.on_guard('/collision_monitor', True, 'answers again')
        assert holds.blocked() == '' and [r[1] for r in reports[-2:]] == ['cleared', 'cleared']
