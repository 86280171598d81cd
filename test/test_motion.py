"""The committed-motion model: its rules, its admission check, and the simulator that obeys it.

The rules are tested on their own (no rclpy, no PyBullet), then against what the PyBullet cell
actually executes: the same trajectories, the start and end of each move to one physics step.
The admission check is then driven by 200 random raw commands through the other arm's
workspace, executed in physics: the measured capsule distance never falls below the margin.
"""
import numpy as np
import numpy.testing as npt
import pytest

from scara_collab.core import collision, motion
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import ik
from scara_collab.core.motion import ArmMotion, CellMotion, Heard, Move
from scara_collab.core.move_time import Refused, stamp_time, start_time
from scara_collab.core.planning import schedule, Timeline
from scara_collab.core.trajectory import joint_move, Trajectory
from scara_collab.sim import CellSim

LEFT, RIGHT = 'scara_left', 'scara_right'
DT = 0.001


def _move(move_id, start, q0, q1, duration=1.0, n=11):
    t = np.linspace(0.0, duration, n)
    q = np.asarray(q0, float) + np.outer(t / duration, np.asarray(q1, float) - q0)
    return Move(move_id, Timeline(start + t, q))


def _sim(cell):
    return CellSim(cell, dict(load_config('simulation'), feed_interval=0.0))


def _pose(cell, robot, xyz):
    sol = ik(cell.arm(robot), xyz)
    assert sol.ok, sol
    return sol.q


# --- the start rule ---------------------------------------------------------------------------
def test_stamp_zero_starts_now_a_future_stamp_waits_a_past_one_starts_late():
    """The start rule: now, at the stamp, or now (late); refused once it would have ended."""
    assert start_time(0.0, 1.0, 5.0, DT) == 5.0
    assert start_time(5.5, 1.0, 5.0, DT) == 5.5
    assert start_time(5.0 - DT / 2, 1.0, 5.0, DT) == 5.0 - DT / 2  # within a step
    assert start_time(4.2, 1.0, 5.0, DT) == 5.0                    # late
    with pytest.raises(Refused, match='ended 0.500 s ago'):
        start_time(3.5, 1.0, 5.0, DT)


def test_a_first_point_after_the_start_is_reached_from_where_the_arm_is():
    """A first point after t = 0 is reached from the measured pose; lateness is counted."""
    m = motion.resolve('a/1', 0.0, [0.5, 1.0], [[1.0, 1.0, 0.1], [2.0, 1.0, 0.1]], now=3.0,
                       dt=DT, q_now=[0.0, 1.0, 0.1])
    npt.assert_allclose(m.timeline.t, [3.0, 3.5, 4.0])
    npt.assert_allclose(m.timeline.q[0], [0.0, 1.0, 0.1])
    assert m.late == 0.0
    assert motion.resolve('a/2', 2.0, [0.0, 1.0], np.zeros((2, 3)), 2.5, DT).late == 0.5


def test_what_is_committed_is_the_running_move_from_now_or_a_hold_where_the_arm_is():
    """A move not yet ended counts from now on; an ended move or none is a hold at its pose."""
    tl = Timeline(np.array([1.0, 2.0, 3.0]), np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]))
    measured = np.array([0.4, 0.5, 0.6])
    arm = ArmMotion(LEFT, np.zeros(3))
    arm.take(Move('a', tl), 1.0)
    now = arm.current(1.5, measured)
    npt.assert_allclose(now.t, [1.5, 2.0, 3.0])
    npt.assert_allclose(now.q[0], [0.5, 0.5, 0.5])  # the move's pose now, not the measured one
    idle = ArmMotion(LEFT, np.zeros(3))
    for motion_of, at in ((arm, 3.0), (arm, 4.0), (idle, 1.5)):
        held = motion_of.current(at, measured)
        assert held.start == held.end == at
        npt.assert_allclose(held.q, [measured])


def test_a_trajectory_without_a_measured_pose_is_taken_as_sent():
    """Without a measured pose the trajectory is taken as sent."""
    t, q = np.array([0.5, 1.0]), np.array([[1.0, 1, 1], [2, 2, 2]])
    npt.assert_allclose(motion.resolve('a', 0.0, t, q, now=2.0, dt=DT).timeline.t, [2.5, 3.0])


# --- one arm --------------------------------------------------------------------------------
def test_a_new_move_takes_over_at_its_start_and_replaces_a_waiting_one():
    """A waiting move is replaced at once; the running one runs until the new one's start."""
    arm = ArmMotion(LEFT, np.zeros(3))
    a = _move('a', 0.0, np.zeros(3), np.ones(3))
    assert arm.take(a, 0.0) is None and arm.running is a
    b = _move('b', 0.6, a.timeline.at(0.6), np.zeros(3))
    c = _move('c', 0.7, a.timeline.at(0.7), np.zeros(3))
    arm.take(b, 0.1)
    assert arm.take(c, 0.2) is b            # a waiting move is replaced at once
    assert arm.running is a and arm.waiting is c
    npt.assert_allclose(arm.motion(0.5).at(0.65), a.timeline.at(0.65))  # a runs until c
    npt.assert_allclose(arm.motion(0.5).at(1.2), c.timeline.at(1.2))
    assert arm.advance(0.69) == []
    assert arm.advance(0.7) == [('started', c)]
    assert arm.advance(1.7) == [('finished', c)] and not arm.active(1.7)
    npt.assert_allclose(arm.rest, c.timeline.q[-1])


def test_hold_drops_both_moves_and_a_brake_runs_at_once(cell):
    """A hold drops the running and the waiting move; a brake runs from now at the limits."""
    cell_arm = cell.leader
    arm = ArmMotion(LEFT, np.zeros(3))
    arm.take(_move('a', 0.0, np.zeros(3), np.ones(3)), 0.0)
    arm.take(_move('b', 2.0, np.ones(3), np.zeros(3)), 0.5)
    assert [m.id for m in arm.hold([0.5, 0.5, 0.5])] == ['a', 'b']
    assert not arm.active(0.5)
    brake = arm.brake(cell_arm, [0.5, 0.5, 0.1], [1.0, -0.5, 0.0], now=0.5)
    assert arm.running is brake and brake.start == 0.5
    assert brake.end == pytest.approx(0.5 + 1.0 / cell_arm.max_acceleration[0])


# --- two arms: admission ----------------------------------------------------------------------
@pytest.fixture
def poses(cell):
    """Each arm's tool well out on its own side, and a pose reaching over the belt."""
    return {'left_out': _pose(cell, LEFT, [2.8, -1.2, 0.4]),
            'left_in': _pose(cell, LEFT, [2.0, 0.25, 0.4]),
            'right_out': _pose(cell, RIGHT, [2.8, 1.2, 0.4]),
            'right_in': _pose(cell, RIGHT, [2.0, -0.25, 0.4])}


def _cell_motion(cell, poses):
    return CellMotion(cell.arms, [poses['left_out'], poses['right_out']],
                      cell.safety_margin, DT)


def _q(cm):
    return {r: a.rest for r, a in cm.arms.items()}


def test_two_moves_into_the_same_place_at_the_same_time_the_second_is_refused(cell, poses):
    """The second of two moves into one place at one time is refused, with the reason."""
    cm = _cell_motion(cell, poses)
    cm.take(LEFT, _move('L', 0.0, poses['left_out'], poses['left_in'], 2.0), 0.0, _q(cm))
    with pytest.raises(Refused, match=r'within 0.1 m of scara_left \(its running move L\)'):
        cm.take(RIGHT, _move('R', 0.5, poses['right_out'], poses['right_in'], 2.0), 0.0,
                _q(cm))
    assert cm[RIGHT].waiting is None  # nothing changed
    # after the left arm is back out, the same move is fine
    cm.take(LEFT, _move('L2', 2.0, poses['left_in'], poses['left_out'], 1.0), 0.0, _q(cm))
    cm.take(RIGHT, _move('R', 3.5, poses['right_out'], poses['right_in'], 2.0), 0.0, _q(cm))


def test_the_leader_does_not_wait_for_a_later_follower_move_judged_at_its_start(cell, poses):
    """The leader ignores a follower move starting later; that one is dropped at its start."""
    cm = _cell_motion(cell, poses)
    follower = _move('R', 1.0, poses['right_out'], poses['right_in'], 2.0)
    cm.take(RIGHT, follower, 0.0, _q(cm))
    # the leader's move starts before the follower's: the follower will yield
    cm.take(LEFT, _move('L', 0.5, poses['left_out'], poses['left_in'], 2.0), 0.0, _q(cm))
    events = []
    for k in range(0, 1200):
        now = round(k * DT, 9)
        q = {r: a.current(now).at(now) for r, a in cm.arms.items()}
        events += cm.advance(now, q)
    assert [(r, e, m.id) for r, e, m, _ in events] == [
        (LEFT, 'started', 'L'), (RIGHT, 'dropped', 'R')]
    assert 'judged again at its start' in events[1][3]
    assert cm[RIGHT].running is None and cm[RIGHT].waiting is None


def test_a_follower_move_starting_first_binds_the_leader(cell, poses):
    """A follower move that starts before the leader's binds the leader (it started first)."""
    cm = _cell_motion(cell, poses)
    cm.take(RIGHT, _move('R', 0.2, poses['right_out'], poses['right_in'], 2.0), 0.0, _q(cm))
    with pytest.raises(Refused, match='its next move'):
        cm.take(LEFT, _move('L', 0.5, poses['left_out'], poses['left_in'], 2.0), 0.0, _q(cm))


def test_a_follower_move_starting_with_the_leaders_leaves_the_follower_on_its_running_move(
        cell, poses):
    """The leader is judged against what the follower runs, not against a follower frozen.

    Both moves are sent for the same instant (two planners answering the same tick, neither
    having heard the other's). The follower's waiting move yields, so the leader is judged
    against the follower's running move carried on, as its planner sees it without the
    waiting move; at its start the waiting move is judged again against the leader's, and the
    arms keep the margin along what they then run.
    """
    start = 0.3
    cm = CellMotion(cell.arms, [poses['left_out'], poses['right_in']], cell.safety_margin, DT)
    q = {LEFT: poses['left_out'], RIGHT: poses['right_in']}
    away = _move('R1', 0.0, poses['right_in'], poses['right_out'], 1.0)  # leaving the belt
    cm.take(RIGHT, away, 0.0, q)
    frozen = away.timeline.at(start)  # where the follower is when both moves start
    assert collision.arm_distance(cell.leader, poses['left_in'], cell.follower,
                                  frozen) < cell.safety_margin
    cm.take(RIGHT, _move('R2', start, frozen, poses['right_out'] + [0.3, 0.0, 0.0]), 0.0, q)
    leader = _move('L', start, poses['left_out'], poses['left_in'], 1.5)
    cm.take(LEFT, leader, 0.0, q)  # admitted: the follower held at ``frozen`` would refuse it
    closest = float('inf')
    for k in range(0, 2500):
        now = round(k * DT, 9)
        pose = {r: a.current(now).at(now) for r, a in cm.arms.items()}
        cm.advance(now, pose)
        closest = min(closest, float(collision.arm_distance(cell.leader, pose[LEFT],
                                                            cell.follower, pose[RIGHT])))
    assert closest >= cell.safety_margin


def test_a_leader_planned_against_a_follower_moving_away_starts_after_it_and_is_admitted(
        cell, poses):
    """The planner applies the priority rule at the start it finds, as the door does.

    The follower stands in the leader's way and has a move out of it waiting to start at the
    leader's wanted start. At that start the move yields (the door sees the follower stand),
    so the leader starts after it (a step on at the least), against the follower moving away;
    the door admits that plan. Planned by the rule at the wanted start only, the leader
    relied on a follower move that does not bind it there, and the door refused it.
    """
    start, now = stamp_time(0.3), 0.0  # as both stamps say it
    in_way = poses['right_in'] + 0.3 * (poses['right_out'] - poses['right_in'])
    assert collision.arm_distance(cell.leader, poses['left_in'], cell.follower,
                                  in_way) < cell.safety_margin
    q = {LEFT: poses['left_out'], RIGHT: in_way}

    def follower_moving_away():
        cm = CellMotion(cell.arms, [poses['left_out'], in_way], cell.safety_margin, DT)
        cm.take(RIGHT, _move('R', start, in_way, poses['right_out'], 1.0), now, q)
        return cm
    cm = follower_moving_away()
    step = _move('L', 0.0, poses['left_out'], poses['left_in'], 1.5).timeline
    traj = Trajectory(step.t, step.q, np.zeros_like(step.q), np.zeros_like(step.q),
                      np.zeros_like(step.q))

    def view(before):
        return cm[RIGHT].motion(now, in_way, before=before)
    plan = motion.schedule_for_door(cell.leader, traj, start, cell.follower, view,
                                    cm[RIGHT].waiting.start, cell.safety_margin, True, 30.0, DT)
    assert plan.start >= start + DT - 1e-12 and plan.start == stamp_time(plan.start)
    assert plan.delay == pytest.approx(plan.start - start)
    cm.take(LEFT, Move('L', Timeline(plan.start + traj.t, traj.q)), now, q)  # admitted
    # the rule applied at the wanted start only: the follower counted as moving away at once
    naive = schedule(cell.leader, traj, start, cell.follower, view(None), cell.safety_margin,
                     True, 30.0)
    assert naive.start < plan.start
    with pytest.raises(Refused, match='where it stands and its next move'):
        follower_moving_away().take(LEFT, Move('L', Timeline(naive.start + traj.t, traj.q)),
                                    now, q)


def test_arms_stopped_too_close_may_only_be_parted(cell, poses):
    """Arms already within the margin: only a move parting them from a still arm is run."""
    near = _pose(cell, LEFT, [2.0, 0.25, 0.4])
    close = _pose(cell, RIGHT, [2.0, 0.38, 0.4])
    cm = CellMotion(cell.arms, [near, close], cell.safety_margin, DT)
    q = {LEFT: near, RIGHT: close}
    assert collision.arm_distance(cell.leader, near, cell.follower, close) < cell.safety_margin
    with pytest.raises(Refused, match='only a move that parts them'):
        cm.take(LEFT, _move('in', 0.0, near, _pose(cell, LEFT, [2.0, 0.4, 0.4]), 1.0), 0.0, q)
    cm.take(LEFT, _move('out', 0.0, near, poses['left_out'], 1.0), 0.0, q)


# --- what a node hears --------------------------------------------------------------------------
def test_heard_follows_the_bridges_word():
    """A node's view: taken as the bridge takes it, corrected by accepted/refused/held."""
    heard = Heard(LEFT, np.zeros(3))
    t, q = np.array([0.0, 1.0]), np.array([np.zeros(3), np.ones(3)])
    m = heard.trajectory('L/1', 2.0, t, q, now=1.0)
    assert heard.arm.waiting is m
    assert heard.status('accepted', 'L/1', now=1.02, start=2.5)  # the bridge's own start
    assert heard.arm.waiting.start == 2.5
    heard.trajectory('L/2', 0.0, t, q + 1, now=1.1)
    assert heard.status('refused', 'L/2', now=1.12)  # undone: L/1 waits again
    assert heard.arm.waiting.id == 'L/1' and heard.arm.running is None
    npt.assert_allclose(heard.motion(3.0).at(3.0), [0.5, 0.5, 0.5])
    assert heard.status('held', 'L/1', now=3.0, q=[0.4, 0.4, 0.4])
    assert not heard.arm.active(3.0)
    # an accepted status heard before its trajectory: the trajectory takes the bridge's start
    assert not heard.status('accepted', 'L/3', now=4.0, start=4.3)
    assert heard.trajectory('L/3', 4.1, t, q, now=4.05).start == 4.3


# --- the simulator executes what the model says ------------------------------------------------
def test_the_simulator_starts_and_ends_each_move_when_the_model_says(cell, poses):
    """The PyBullet cell runs each move from the model's start to its end, to a servo tick."""
    sim = _sim(cell)
    sim.reset_arm(LEFT, poses['left_out'])
    sim.reset_arm(RIGHT, poses['right_out'])
    arm = cell.leader
    a = joint_move(arm, poses['left_out'], _pose(cell, LEFT, [2.5, -1.2, 0.3]))
    b = joint_move(arm, a.q[-1], _pose(cell, LEFT, [3.0, -0.9, 0.3]))
    sim.execute(LEFT, 0.05 + a.t, a.q, a.qd, a.qdd, 'a', 0.05)
    b_start = round(0.05 + 0.5 * a.duration, 3)
    moving = None
    last_ref = sim.reference(LEFT)[0]
    while sim.time < b_start - 0.01 - 1e-9:  # b is sent 10 ms before its start
        sim.step(1)
        ref = sim.reference(LEFT)[0]
        if moving is None and not np.array_equal(ref, last_ref):
            moving = sim.time
        last_ref = ref
    ref_b = joint_move(arm, sim.motion[LEFT].running.timeline.at(b_start), b.q[-1])
    sim.execute(LEFT, b_start + ref_b.t, ref_b.q, ref_b.qd, ref_b.qdd, 'b', b_start)
    predicted = sim.motion[LEFT].motion(sim.time)
    last_change = None
    while sim.time < b_start + ref_b.duration + 0.1:
        sim.step(1)
        ref = sim.reference(LEFT)[0]
        if not np.array_equal(ref, last_ref):
            last_change = sim.time
        last_ref = ref
        if abs(sim.time - (b_start + 0.1)) < DT / 2:  # b has taken over: on b's path
            npt.assert_allclose(ref, ref_b.q[np.searchsorted(ref_b.t, 0.1)], atol=0.02)
    servo_dt = 1.0 / float(load_config('simulation')['servo_rate'])
    assert abs(moving - 0.05) <= servo_dt + DT   # a starts at its stamp
    # the reference stops changing when b ends (sampled at the servo's ticks)
    assert abs(last_change - (b_start + ref_b.duration)) <= servo_dt + DT
    npt.assert_allclose(predicted.at(sim.time), b.q[-1], atol=1e-9)
    npt.assert_allclose(sim.arm_state(LEFT)[0], b.q[-1], atol=2e-3)


def test_the_simulator_drops_a_move_made_unsafe_reports_it_once_and_refuses_it_anew(
        cell, poses):
    """A follower move waiting for its start, then a leader move into the same place.

    The leader's starts first (the follower yields): the follower's is dropped as it would
    take over, reported once (for the bridge's ``refused`` status), and refused if sent again.
    """
    sim = _sim(cell)
    sim.reset_arm(LEFT, poses['left_out'])
    sim.reset_arm(RIGHT, poses['right_out'])
    lead = joint_move(cell.leader, poses['left_out'], poses['left_in'])
    follow = joint_move(cell.follower, poses['right_out'], poses['right_in'])
    sim.execute(RIGHT, 0.5 + follow.t, follow.q, follow.qd, follow.qdd, 'R', 0.5)
    sim.execute(LEFT, 0.2 + lead.t, lead.q, lead.qd, lead.qdd, 'L', 0.2)  # leader first
    sim.step(int(0.6 / DT))
    assert not sim.active(RIGHT)
    dropped = [(r, m.id) for r, ev, m, _ in sim.motion.poll(sim.time) if ev == 'dropped']
    assert dropped == [(RIGHT, 'R')]
    assert [ev for _, ev, m, _ in sim.motion.poll(sim.time) if ev == 'dropped'] == []
    with pytest.raises(Refused, match='within'):
        sim.execute(RIGHT, sim.time + follow.t, follow.q, follow.qd, follow.qdd, 'R2', 0.0)


def test_a_move_must_begin_where_the_arm_will_be_at_its_start(cell, poses):
    """A re-time of a move that has started, sent while the arm is still near its start.

    The arm has barely left the first pose when it arrives (the measured pose is within the
    start tolerance of it), but by its start the running move has taken the arm far on: it is
    refused at the door, so the reference never jumps back.
    """
    sim = _sim(cell)
    sim.reset_arm(LEFT, poses['left_out'])
    sim.reset_arm(RIGHT, poses['right_out'])
    a = joint_move(cell.follower, poses['right_out'], poses['right_in'])
    sim.execute(RIGHT, a.t, a.q, a.qd, a.qdd, 'R', 0.0)
    sim.step(30)  # it has started
    tol = float(load_config('simulation')['start_tolerance'])
    assert np.max(np.abs(sim.arm_state(RIGHT)[0] - a.q[0])) < tol
    later = sim.time + 0.5 * a.duration
    with pytest.raises(ValueError, match='where its running move puts the arm at its start'):
        sim.execute(RIGHT, later + a.t, a.q, a.qd, a.qdd, 'R', later)
    assert sim.motion[RIGHT].waiting is None
    # from where the running move will be, the same move is admitted
    there = sim.motion[RIGHT].running.timeline.at(later)
    b = joint_move(cell.follower, there, poses['right_out'])
    sim.execute(RIGHT, later + b.t, b.q, b.qd, b.qdd, 'R2', later)
    assert sim.motion[RIGHT].waiting.id == 'R2'


def test_a_waiting_move_is_dropped_if_the_arm_is_not_at_its_first_point_when_it_takes_over(
        cell, poses):
    """Measured again at the start: an arm that lags (or was pushed) does not jump."""
    cm = CellMotion(cell.arms, [poses['left_out'], poses['right_out']], cell.safety_margin, DT,
                    start_tolerance=0.05)
    b = _move('R', 1.0, poses['right_out'], poses['right_in'])
    cm.take(RIGHT, b, 0.0, _q(cm))
    pushed = dict(_q(cm), **{RIGHT: poses['right_out'] + [0.1, 0.0, 0.0]})
    [(robot, event, move, reason)] = cm.advance(1.0, pushed)
    assert (robot, event, move) == (RIGHT, 'dropped', b)
    assert 'starts 0.1000 away from the measured position of joint 1' in reason
    assert not cm[RIGHT].active(1.0)
    again = b.shifted(2.0)
    cm.take(RIGHT, again, 1.0, _q(cm))
    [(robot, event, move, _)] = cm.advance(2.0, _q(cm))  # where the arm is: it starts
    assert (robot, event, move.id, move.start) == (RIGHT, 'started', 'R', 2.0)


# --- 200 raw commands through the other arm's workspace ----------------------------------------
def test_random_raw_commands_never_bring_the_arms_within_the_margin(cell):
    """200 raw commands through the other arm's path never break the margin in physics.

    Joint moves to random targets over the belt, sent to either arm at random moments (often
    mid-motion, often into the other arm's path), executed in PyBullet: the capsule distance
    measured every 5 ms never falls below the safety margin.
    """
    rng = np.random.default_rng(7)
    sim = _sim(cell)
    sim.reset_arm(LEFT, _pose(cell, LEFT, [2.8, -1.2, 0.4]))
    sim.reset_arm(RIGHT, _pose(cell, RIGHT, [2.8, 1.2, 0.4]))
    admitted = refused = 0
    worst = np.inf
    for _ in range(200):
        robot = LEFT if rng.random() < 0.5 else RIGHT
        arm = cell.arm(robot)
        side = np.sign(arm.base_position[1])
        target = [rng.uniform(1.0, 3.0), side * rng.uniform(-0.9, 0.9), rng.uniform(0.3, 0.6)]
        try:
            q0 = sim.reference(robot)[0] if sim.active(robot) else sim.arm_state(robot)[0]
            goal = ik(arm, target, q_current=q0)
            if not goal.ok:
                continue
            traj = joint_move(arm, sim.arm_state(robot)[0], goal.q)
            stamp = sim.time + rng.choice([0.0, 0.0, rng.uniform(0.0, 0.5)])
            sim.execute(robot, stamp + traj.t, traj.q, traj.qd, traj.qdd, f'{robot}/{_}', stamp)
            admitted += 1
        except Refused:
            refused += 1
        except ValueError:
            continue  # e.g. starting too far from a moving arm: refused for another reason
        for _k in range(int(rng.uniform(0.05, 0.6) / DT / 5)):
            sim.step(5)
            q, _qd = sim._read()
            worst = min(worst, float(collision.arm_distance(cell.leader, q[0], cell.follower,
                                                            q[1])))
        sim.motion.poll(sim.time)
    print(f'admitted {admitted}, refused {refused}, closest {worst:.4f} m')
    assert admitted >= 40 and refused >= 20
    assert worst >= cell.safety_margin


def test_an_arm_behind_on_its_own_clock_runs_its_moves_that_much_later_in_sim_time(cell, poses):
    """A lag of 0.5 s: a move stamped 1.0 starts at sim 1.5, and the other arm sees it so."""
    cm = _cell_motion(cell, poses)
    lead = cm[LEFT]
    lead.lag = 0.5
    cm.take(LEFT, _move('L', 1.0, poses['left_out'], poses['left_in'], 1.0), 0.0, _q(cm))
    assert lead.waiting is not None and lead.waiting_start == 1.5
    assert not lead.advance(1.2) and lead.advance(1.5)[0][0] == 'started'
    seen = lead.current(2.0)  # half way through it in trajectory time: sim 2.0 -> 1.5
    np.testing.assert_allclose(seen.t[[0, -1]], [2.0, 2.5])
    np.testing.assert_allclose(seen.q[0], lead.running.timeline.at(1.5))
    # the follower is judged against the leader where the leader will really be: late
    for lag, admitted in ((0.0, True), (0.5, False)):
        cm = CellMotion(cell.arms, [poses['left_in'], poses['right_out']], cell.safety_margin,
                        DT)
        cm[LEFT].lag = lag  # the leader leaves the belt in trajectory time 0.0 .. 1.0
        cm.take(LEFT, _move('L', 0.0, poses['left_in'], poses['left_out'], 1.0), 0.0,
                {LEFT: poses['left_in'], RIGHT: poses['right_out']})
        enter = _move('R', 0.4, poses['right_out'], _pose(cell, RIGHT, [2.0, 0.25, 0.4]), 0.15)
        try:
            cm.take(RIGHT, enter, 0.0, {LEFT: poses['left_in'], RIGHT: poses['right_out']})
            assert admitted
        except Refused as exc:
            assert not admitted and 'within' in str(exc)
    # an observer hears the clock too: the trajectory time it reports, the sim time it means
    heard = Heard(LEFT, poses['left_out'], dt=DT)
    heard.on_clock(0.5)
    move = heard.trajectory('L', 1.0, [0.0, 1.0], [poses['left_out'], poses['left_in']], 0.0)
    assert move.start == 1.0 and heard.waiting_start == 1.5
    assert heard.motion(1.2).end == pytest.approx(2.5)
