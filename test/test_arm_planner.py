"""One arm's planner without ROS: requests in, moves and statuses out, on a clock of the test's.

The leader (left) and the follower (right) are driven by their observations alone: joint
states, targets and offered plans, the other arm's trajectories and the bridge's statuses.
What comes out is checked command by command: the move sent and its start, the status and its
reason.
"""
from dataclasses import replace

import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core.arm_planner import (Answers, ArmPlanner, HISTORY, HoldArm,
                                           PlannerSettings, SendMove, Status)
from scara_collab.core.collision import arm_distance
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.move_time import Leads
from scara_collab.core.planning import plan_path
from scara_collab.core.trajectory import joint_move

LEAD = 0.05
#: s, the least time between sending a move and its start
MARGIN = 0.02
#: s between the physics steps
DT = 0.001
#: tool positions: each arm well out on its side, and reaching over the belt's centre line
OUT = {'scara_left': [2.8, -1.2, 0.4], 'scara_right': [2.8, 1.2, 0.4]}
CENTRE = {'scara_left': [2.6, -0.03, 0.4], 'scara_right': [2.6, 0.03, 0.4]}
ACROSS = {'scara_left': [2.0, 0.25, 0.4], 'scara_right': [2.0, -0.25, 0.4]}


class Clock:
    """The sim clock of a test: ``t`` s, moved on by the test."""

    def __init__(self, t: float = 10.0):
        """Start at ``t``."""
        self.t = t

    def __call__(self) -> float:
        """Return the time now, s."""
        return self.t


def _settings(cell, planning_lead=LEAD, send_margin=MARGIN, **overrides) -> PlannerSettings:
    cfg = load_config('controllers')
    leads = Leads(planning=planning_lead, send=send_margin)
    return replace(PlannerSettings('line_or_joint', leads, 30.0, 60.0,
                                   cell.safety_margin + float(cfg['planning_buffer']),
                                   cfg['trajectory']), **overrides)


def _pose(arm, xyz):
    sol = ik(arm, xyz)
    assert sol.ok, sol
    return sol.q


def _planner(cell, robot, clock, at=None, other_at=None, **settings):
    """Return ``robot``'s planner after a joint state: tools at ``at`` and ``other_at``."""
    arm = cell.arm(robot)
    other = next(a for a in cell.arms if a is not arm)
    p = ArmPlanner(arm, other, arm is cell.leader, _settings(cell, **settings), clock, DT)
    if at is not None:
        assert p.on_joint_state(_pose(arm, at), _pose(other, other_at), clock()) == []
    return p


def _of(commands, kind):
    return [c for c in commands if isinstance(c, kind)]


def _status(commands) -> Status:
    statuses = _of(commands, Status)
    assert len(statuses) == 1, commands
    return statuses[0]


def _sent(commands) -> SendMove:
    moves = _of(commands, SendMove)
    assert len(moves) == 1, commands
    return moves[0]


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def _target(p, xyz, stamp=0.0, frame='world', frame_error=''):
    return p.on_target(_ns(stamp), stamp, xyz, frame, frame_error)


def _hear(p, move_id, start, traj):
    """Hear the other arm's trajectory ``traj`` stamped ``start`` now; return the commands."""
    return p.on_other_trajectory(move_id, start, traj.t, traj.q)


@pytest.fixture
def clock():
    """Return a clock at t = 10 s."""
    return Clock()


@pytest.fixture
def leader(cell, clock):
    """Return the left planner, both arms out on their own sides."""
    return _planner(cell, 'scara_left', clock, OUT['scara_left'], OUT['scara_right'])


@pytest.fixture
def follower(cell, clock):
    """Return the right planner, both arms out on their own sides."""
    return _planner(cell, 'scara_right', clock, OUT['scara_right'], OUT['scara_left'])


# --- a move planned ------------------------------------------------------------------------------
def test_a_target_is_planned_from_the_arm_and_sent_with_its_status(cell, clock, leader):
    """A line from the measured joints, starting the lead after now, sent then reported."""
    out = _target(leader, [3.0, -1.0, 0.3])
    assert [type(c) for c in out] == [SendMove, Status]
    move, st = out
    request = _ns(clock.t)  # stamped zero: the receipt time is the request
    assert move.request == st.request == request
    assert move.plan.start == pytest.approx(clock.t + LEAD) and move.plan.delay == 0.0
    assert_allclose(move.plan.traj.q[0], _pose(cell.leader, OUT['scara_left']))
    assert_allclose(fk(cell.leader, move.plan.traj.q[-1]), [3.0, -1.0, 0.3], atol=1e-6)
    assert st == Status('planned', request, '', move.plan.start, move.plan.end, 0.0, 'line')
    assert leader.committed.plan == move.plan


def test_a_requested_start_is_kept_and_a_past_one_starts_after_the_send_margin(
        cell, clock, leader):
    """A stamp at least the send margin ahead is the start, a nearer one that margin later.

    Planning took the time the lead was for; the measured start lateness comes on top.
    """
    later = _sent(_target(leader, [3.0, -1.0, 0.3], stamp=12.5))
    assert later.request == _ns(12.5) and later.plan.start == 12.5
    clock.t = 20.0
    kept = _sent(_target(leader, [2.8, -1.2, 0.4], stamp=20.03))
    assert kept.plan.start == pytest.approx(20.03)
    clock.t = 30.0
    soon = _sent(_target(leader, [3.0, -1.0, 0.3], stamp=29.99))
    assert soon.plan.start == pytest.approx(30.0 + MARGIN)
    leader.on_own_execution('accepted', soon.request, 30.1, stamp=30.02)
    clock.t = 40.0
    late = _sent(_target(leader, [2.8, -1.2, 0.4], stamp=40.01))
    assert late.plan.start == pytest.approx(40.0 + MARGIN + 0.08)


def test_a_line_the_arm_cannot_follow_becomes_a_joint_move_or_is_refused(cell, clock):
    """Across the inner reach: ``line_or_joint`` makes a joint move, ``line`` refuses."""
    far = [1.4, -1.0, 0.4]
    for mode, expected in (('line_or_joint', 'joint move'), ('line', None)):
        p = _planner(cell, 'scara_left', Clock(), [2.8, -2.5, 0.4], OUT['scara_right'],
                     mode=mode)
        st = _status(_target(p, far))
        if expected:
            assert st.state == 'planned' and st.kind == expected
        else:
            assert st.state == 'refused' and st.reason


# --- requests answered once ----------------------------------------------------------------------
def test_a_resent_request_is_answered_again_not_planned_again(clock, leader):
    """The same stamp again: its last status once more, marked repeated; nothing is sent."""
    first = _status(_target(leader, [3.0, -1.0, 0.3], stamp=11.0))
    clock.t = 10.5
    again = _target(leader, [3.3, -0.5, 0.3], stamp=11.0)
    assert again == [replace(first, repeated=True)]


def test_targets_stamped_zero_are_distinct_requests_even_in_one_nanosecond(clock, leader):
    """Each target stamped zero gets its own id: the receipt time, or one ns after the last.

    The second comes before the first has begun: it takes its place.
    """
    a = _status(_target(leader, [3.0, -1.0, 0.3]))
    out = _target(leader, [3.3, -0.5, 0.3])
    gone, b = _of(out, Status)
    assert (a.request, b.request) == (_ns(clock.t), _ns(clock.t) + 1)
    assert (a.state, gone.state, gone.request, b.state) == ('planned', 'superseded', a.request,
                                                            'planned')


def test_a_request_before_the_sent_move_began_takes_its_place(clock, leader):
    """A move sent for t = 11 s has not begun at 10.5 s: a new request takes its place.

    The arm is held where it is (the bridge drops the waiting move), the first request is
    superseded and the new one planned from there; once the new move has begun, a request
    queues behind it.
    """
    first = _sent(_target(leader, [3.0, -1.0, 0.3], stamp=11.0))
    clock.t = 10.5
    out = _target(leader, [3.3, -0.5, 0.3])
    (hold,) = _of(out, HoldArm)
    assert_allclose(hold.q, leader.joints)
    gone, new = _of(out, Status)
    assert (gone.state, gone.request) == ('superseded', first.request)
    assert new.state == 'planned' and leader.committed.request == new.request
    clock.t = new.start + 0.05
    assert _status(_target(leader, [3.0, -1.0, 0.3])).state == 'queued'


def test_the_answers_keep_the_last_requests_only():
    """Answers keep :data:`HISTORY` requests: the oldest is forgotten, then planned anew."""
    answers = Answers()
    for request in range(1, HISTORY + 2):
        answers.keep(Status('refused', request, 'no'))
    assert answers.last(1) is None and answers.last(2).reason == 'no'
    answers.keep(Status('planned', 2))
    answers.keep(Status('queued', 0))  # no request: not kept
    assert answers.last(2).state == 'planned' and answers.last(0) is None


# --- refusals ------------------------------------------------------------------------------------
@pytest.mark.parametrize('xyz, frame_error, reason', [
    ([float('nan'), -1.0, 0.4], '', 'non-finite target [nan, -1.0, 0.4]'),
    ([3.0, -1.0, 0.4], "unknown frame 'map'", "unknown frame 'map'"),
    ([9.0, -2.0, 0.4], '', 'outer reach'),
    ([2.0, -2.0, 0.4], '', 'inner reach'),
    ([3.0, -1.0, 1.5], '', 'quill travel'),
])
def test_a_bad_target_is_refused_with_the_reason_and_nothing_is_sent(leader, xyz, frame_error,
                                                                     reason):
    """A non-finite, unknown-frame or unreachable target: refused, the arm keeps its place."""
    out = _target(leader, xyz, frame_error=frame_error)
    st = _status(out)
    assert st.state == 'refused' and reason in st.reason
    assert _of(out, SendMove) == [] and leader.committed is None


def test_before_any_joint_state_every_request_is_refused(cell, clock):
    """Without a joint state nothing can be planned: the bridge is not up."""
    p = _planner(cell, 'scara_left', clock)
    st = _status(_target(p, [3.0, -1.0, 0.3]))
    assert (st.state, st.reason) == ('refused', 'no joint state yet (is the bridge up?)')


def test_a_base_frame_target_is_planned_in_the_base_frame(cell, leader):
    """A target in the arm's base frame goes to the same place as its world coordinates."""
    world = np.array([3.0, -1.0, 0.3])
    move = _sent(_target(leader, world - cell.leader.base_position, frame='base'))
    assert_allclose(fk(cell.leader, move.plan.traj.q[-1]), world, atol=1e-6)


# --- offered plans -------------------------------------------------------------------------------
def _offer(p, traj, stamp, **spoil):
    arrays = {'t': traj.t, 'q': traj.q, 'qd': traj.qd, 'qdd': traj.qdd, **spoil}
    return p.on_offer(_ns(stamp), stamp, **arrays)


def test_an_offer_from_where_the_arm_is_is_sent_as_it_is(cell, leader):
    """The job's plan starting at the arm's joints is scheduled, not planned again."""
    plan = plan_path(cell.leader, leader.joints, [3.3, -0.6, 0.45], mode='line_or_joint')
    move = _sent(_offer(leader, plan, 11.0))
    assert move.request == _ns(11.0) and move.plan.start == 11.0
    assert_allclose(move.plan.traj.q, plan.q)
    assert_allclose(move.plan.traj.qd, plan.qd)


def test_an_offer_from_elsewhere_or_in_another_mode_is_planned_again_to_its_end(cell, clock):
    """An offer not starting at the arm, or any offer in ``line`` mode: planned to its end."""
    arm = cell.leader
    for mode, shift in (('line_or_joint', 0.05), ('line', 0.0)):
        p = _planner(cell, 'scara_left', Clock(), OUT['scara_left'], OUT['scara_right'],
                     mode=mode)
        plan = plan_path(arm, p.joints + [shift, 0.0, 0.0], [3.3, -0.6, 0.45])
        move = _sent(_offer(p, plan, 11.0))
        assert_allclose(move.plan.traj.q[0], p.joints)
        assert_allclose(move.plan.traj.p[-1], plan.p[-1], atol=1e-6)


@pytest.mark.parametrize('spoil, reason', [
    ({'qd': None}, 'offered trajectory: an offered move needs velocities and accelerations'),
    ({'error': 'trajectory has no points'}, 'offered trajectory: trajectory has no points'),
    ('outside', 'offered trajectory: an offered move leaves the joint limits'),
])
def test_a_malformed_offer_is_refused_with_the_reason(cell, leader, spoil, reason):
    """An offer that is not a plan, or a message that could not be read, is refused."""
    plan = plan_path(cell.leader, leader.joints, [3.3, -0.6, 0.45])
    if spoil == 'outside':
        q = plan.q.copy()
        q[-1, 2] = cell.leader.upper[2] + 0.01
        spoil = {'q': q}
    if 'error' in spoil:
        out = leader.on_offer(_ns(11.0), 11.0, error=spoil['error'])
    else:
        out = _offer(leader, plan, 11.0, **spoil)
    st = _status(out)
    assert (st.state, st.request) == ('refused', _ns(11.0)) and st.reason.startswith(reason)
    assert _offer(leader, plan, 11.0) == [replace(st, repeated=True)]  # answered, not planned


# --- queueing behind the arm's own move ----------------------------------------------------------
def test_a_target_during_a_move_is_queued_then_planned_when_it_ends(cell, clock, leader):
    """The bridge replaces a running trajectory: the next target waits for the move's end."""
    first = _sent(_target(leader, [3.0, -1.0, 0.3]))
    clock.t = first.plan.start + 0.1
    st = _status(_target(leader, [3.3, -0.5, 0.3], stamp=clock.t))
    assert st.state == 'queued' and f't={first.plan.end:.3f} s' in st.reason
    q_end = first.plan.traj.q[-1]
    other = _pose(cell.follower, OUT['scara_right'])
    assert leader.on_joint_state(q_end, other, first.plan.end - 0.01) == []  # still running
    clock.t = first.plan.end
    out = leader.on_joint_state(q_end, other, first.plan.end)
    move = _sent(out)
    assert move.request == st.request and _status(out).state == 'planned'
    assert move.plan.start == pytest.approx(clock.t + MARGIN)  # its stamp has passed
    assert_allclose(move.plan.traj.q[0], q_end)


def test_a_newer_target_supersedes_the_queued_one(clock, leader):
    """Only the newest target waits behind the running move; the one it replaces is told."""
    _target(leader, [3.0, -1.0, 0.3])
    clock.t += 0.1
    old = _status(_target(leader, [3.3, -0.5, 0.3], stamp=10.1))
    out = _target(leader, [2.9, -0.8, 0.3], stamp=10.2)
    assert [(s.state, s.request) for s in out] == [('superseded', old.request),
                                                   ('queued', _ns(10.2))]
    assert out[0].reason == f'replaced by request {_ns(10.2)}'
    assert leader.queued.request == _ns(10.2)


@pytest.mark.parametrize('state', ['refused', 'preempted', 'held'])
def test_once_the_bridge_drops_the_move_the_next_target_is_planned_at_once(clock, leader,
                                                                           state):
    """A move refused, preempted or held no longer runs: nothing to queue behind."""
    first = _sent(_target(leader, [3.0, -1.0, 0.3]))
    clock.t += 0.1
    assert leader.on_own_execution(state, first.request) == []
    assert _status(_target(leader, [3.3, -0.5, 0.3])).state == 'planned'


def test_a_move_asked_while_the_arm_brakes_is_planned_from_where_it_stops(cell, clock, leader):
    """Held and braking until t = 10.4: a target waits for it, then starts from the arm at rest.

    Planned at once from the joints measured while the arm still brakes, the move would start
    where the arm no longer is when it starts, and the bridge would refuse it.
    """
    first = _sent(_target(leader, [3.0, -1.0, 0.3]))
    clock.t += 0.1
    leader.on_own_execution('held', first.request, end=10.4)
    st = _status(_target(leader, [3.3, -0.5, 0.3], stamp=10.1))
    assert (st.state, st.reason) == ('queued', 'behind a brake (at rest t=10.400 s)')
    stopped = _pose(cell.leader, [3.1, -0.9, 0.3])
    other = _pose(cell.follower, OUT['scara_right'])
    assert leader.on_joint_state(stopped, other, 10.3) == []  # still braking
    clock.t = 10.4
    move = _sent(leader.on_joint_state(stopped, other, 10.4))
    assert_allclose(move.plan.traj.q[0], stopped)


def test_a_status_of_another_move_changes_nothing(clock, leader):
    """The bridge's word on another request (an old move) does not touch the current one."""
    first = _sent(_target(leader, [3.0, -1.0, 0.3]))
    assert leader.on_own_execution('refused', first.request - 1) == []
    assert leader.on_own_execution('accepted', first.request + 1, first.plan.start + 1.0,
                                   first.plan.start) == []
    assert leader.committed.plan == first.plan


# --- a late start --------------------------------------------------------------------------------
def test_a_late_start_rebases_the_move_and_lengthens_the_lead(cell, clock, leader):
    """Started late by the bridge: re-reported at its real start; the next lead adds it."""
    first = _sent(_target(leader, [3.0, -1.0, 0.3], stamp=11.0))
    out = leader.on_own_execution('accepted', first.request, 11.2, stamp=11.0)
    st = _status(out)
    assert (st.state, st.start, st.kind) == ('planned', 11.2, 'line')
    assert st.end == pytest.approx(first.plan.end + 0.2)
    assert st.delay == pytest.approx(0.2) and st.reason == 'started 0.200 s late by the bridge'
    assert _of(out, SendMove) == []  # the bridge runs it already
    clock.t = st.end + 1.0
    second = _sent(_target(leader, [3.3, -0.5, 0.3]))
    assert second.plan.start == pytest.approx(clock.t + LEAD + 0.2)


def test_an_on_time_start_shortens_the_lead_again_only_when_stamped(cell, clock, leader):
    """On-time starts of stamped moves push a late one out of the window; unstamped do not."""
    first = _sent(_target(leader, [3.0, -1.0, 0.3], stamp=11.0))
    leader.on_own_execution('accepted', first.request, 11.1, stamp=11.0)
    assert leader.time.late.worst == pytest.approx(0.1)
    for k in range(2 * leader.time.late.window - 2):
        leader.on_own_execution('accepted', first.request, 11.1,
                                stamp=11.1 if k % 2 == 0 else None)
    assert leader.time.late.worst == pytest.approx(0.1)  # 19 on-time after it
    leader.on_own_execution('accepted', first.request, 11.1, stamp=11.1)
    assert leader.time.late.worst == 0.0


# --- the other arm -------------------------------------------------------------------------------
def _move(arm, xyz_from, xyz_to, back=False):
    """Return a joint move of ``arm``'s tool between two places (and back, if ``back``)."""
    q0, q1 = _pose(arm, xyz_from), _pose(arm, xyz_to)
    there = joint_move(arm, q0, q1, dt=0.01)
    if not back:
        return there
    home = joint_move(arm, q1, q0, dt=0.01)
    return type(there)(np.concatenate([there.t, there.t[-1] + 0.5 + home.t]),
                       np.vstack([there.q, home.q]), np.vstack([there.qd, home.qd]),
                       np.vstack([there.qdd, home.qdd]), np.vstack([there.p, home.p]))


def test_the_follower_yields_to_a_leader_move_through_its_path(cell, clock, follower):
    """A leader move across the belt: the follower's move there starts after it, delayed."""
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)
    _hear(follower, 'scara_left/1', 10.0, leader_move)
    out = _target(follower, ACROSS['scara_right'])
    move, st = _sent(out), _status(out)
    assert st.state == 'planned' and st.delay > 0 and move.plan.delay == st.delay
    assert move.plan.start == pytest.approx(10.0 + LEAD + st.delay)
    assert move.plan.start > 10.0 + leader_move.t[-1] - 2.0  # after the leader turned back


def test_the_leader_ignores_a_follower_move_that_starts_after_its_own(cell, clock, leader):
    """The priority rule: a follower move starting later yields; one started first binds."""
    later = _move(cell.follower, OUT['scara_right'], ACROSS['scara_right'])
    _hear(leader, 'scara_right/1', 10.5, later)
    assert _sent(_target(leader, ACROSS['scara_left'])).plan.delay == 0.0
    p = _planner(cell, 'scara_left', Clock(), OUT['scara_left'], OUT['scara_right'])
    _hear(p, 'scara_right/1', 10.0, later)  # starts before the leader's move would
    st = _status(_target(p, ACROSS['scara_left']))
    assert st.state == 'waiting' or st.delay > 0


def test_a_move_blocked_by_the_other_arms_pose_waits_and_goes_when_it_leaves(cell, clock):
    """The leader stands where the follower must go: it waits, then goes once the leader leaves.

    The waiting is reported once; the delay counts from the first try.
    """
    p = _planner(cell, 'scara_right', clock, OUT['scara_right'], CENTRE['scara_left'])
    st = _status(_target(p, CENTRE['scara_right']))
    assert st.state == 'waiting' and st.reason.startswith('scara_left blocks it: no start within '
                                                          '30 s keeps 0.13 m')
    assert p.blocked.request == st.request
    clock.t = 11.0
    stay = _move(cell.leader, CENTRE['scara_left'], [2.6, -0.05, 0.4])
    assert _hear(p, 'scara_left/1', 0.0, stay) == []  # still in the way: no second report
    clock.t = 12.0
    away = _move(cell.leader, [2.6, -0.05, 0.4], OUT['scara_left'])
    out = _hear(p, 'scara_left/2', 0.0, away)
    move, done = _sent(out), _status(out)
    assert (done.state, done.request) == ('planned', st.request) and p.blocked is None
    assert done.delay == pytest.approx(move.plan.start - (10.0 + LEAD))
    assert move.plan.start == pytest.approx(12.0 + LEAD)  # as soon as it is heard leaving


def test_a_move_blocked_longer_than_max_wait_is_refused(cell, clock):
    """Still blocked after ``max_wait``: refused, naming the other arm and the time."""
    p = _planner(cell, 'scara_right', clock, OUT['scara_right'], CENTRE['scara_left'],
                 max_wait=5.0)
    request = _status(_target(p, CENTRE['scara_right'])).request
    clock.t = 16.0
    st = _status(_hear(p, 'scara_left/1', 0.0,
                       _move(cell.leader, CENTRE['scara_left'], [2.6, -0.05, 0.4])))
    assert (st.state, st.request) == ('refused', request)
    assert st.reason == 'scara_left has blocked the move for 5.9 s' and p.blocked is None


def test_a_newer_target_supersedes_the_waiting_one(cell, clock):
    """A new target replaces a move waiting for the other arm; the waiting one is told."""
    p = _planner(cell, 'scara_right', clock, OUT['scara_right'], CENTRE['scara_left'])
    waiting = _status(_target(p, CENTRE['scara_right']))
    out = _target(p, [3.0, 1.0, 0.3], stamp=10.5)
    assert [s.state for s in _of(out, Status)] == ['superseded', 'planned']
    assert _of(out, Status)[0].request == waiting.request and p.blocked is None


def test_a_trajectory_of_the_other_arm_that_has_ended_is_ignored(cell, clock):
    """A trajectory that would have ended is refused by the bridge: nothing is retried."""
    p = _planner(cell, 'scara_right', clock, OUT['scara_right'], CENTRE['scara_left'])
    _target(p, CENTRE['scara_right'])
    old = _move(cell.leader, CENTRE['scara_left'], OUT['scara_left'])
    assert _hear(p, 'scara_left/1', 10.0 - old.t[-1] - 1.0, old) == []
    assert p.blocked is not None


def test_the_follower_re_times_its_move_for_a_new_leader_move(cell, clock, follower):
    """A leader move heard after the follower's was sent, before it started: delayed."""
    first = _sent(_target(follower, ACROSS['scara_right'], stamp=11.0))
    assert first.plan.delay == 0.0
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)
    out = _hear(follower, 'scara_left/1', 10.5, leader_move)
    move, st = _sent(out), _status(out)
    assert move.request == first.request and st.state == 'planned'
    assert st.reason == 're-timed for a new scara_left move'
    assert move.plan.start > first.plan.start and st.delay == move.plan.start - 11.0


def test_a_re_time_the_bridge_refuses_leaves_the_first_move_committed(cell, clock, follower):
    """The first move had started at the bridge after all: its re-time is refused at the door.

    The planner keeps the first move as the arm's commitment (it runs), not nothing; the
    first move's own word, heard after the re-time left, does not undo the re-time.
    """
    first = _sent(_target(follower, ACROSS['scara_right'], stamp=11.0))
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)
    again = _sent(_hear(follower, 'scara_left/1', 10.5, leader_move))
    assert follower.committed.plan == again.plan and follower.committed.retimed == first.plan
    assert follower.on_own_execution('accepted', first.request, 11.0, stamp=11.0) == []
    assert follower.committed.plan == again.plan  # the first one's acceptance: still re-timed
    follower.on_own_execution('refused', first.request)
    assert follower.committed.plan == first.plan and follower.committed.retimed is None
    clock.t = 10.8
    queued = _status(_target(follower, [3.0, 1.0, 0.3]))
    assert queued.state == 'queued'  # behind the move that runs


def test_an_accepted_re_time_is_the_arms_commitment(cell, clock, follower):
    """Once the bridge accepts the re-timed move, a later refusal of it leaves nothing."""
    first = _sent(_target(follower, ACROSS['scara_right'], stamp=11.0))
    again = _sent(_hear(follower, 'scara_left/1', 10.5, _move(
        cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)))
    follower.on_own_execution('accepted', first.request, again.plan.start,
                              stamp=again.plan.start)
    assert follower.committed.retimed is None
    follower.on_own_execution('refused', first.request)  # dropped as it would take over
    assert follower.committed is None


def test_a_move_starting_within_the_measured_lateness_is_not_re_timed(cell, clock, follower):
    """The bridge may have started it already: its judgement at the start decides instead."""
    first = _sent(_target(follower, ACROSS['scara_right'], stamp=10.3))
    follower.on_own_execution('accepted', first.request, 10.5, stamp=10.0)
    clock.t = 10.1
    assert _hear(follower, 'scara_left/1', 10.2, _move(
        cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)) == []


def test_the_follower_holds_when_a_new_leader_move_leaves_no_start(cell, clock, follower):
    """A leader move ending where the follower's goes: the follower holds and waits."""
    first = _sent(_target(follower, ACROSS['scara_right'], stamp=11.0))
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'])
    out = _hear(follower, 'scara_left/1', 10.5, leader_move)
    assert [type(c) for c in out] == [HoldArm, Status]
    assert_allclose(out[0].q, follower.joints)
    assert (out[1].state, out[1].request) == ('waiting', first.request)
    assert follower.committed is None and follower.blocked.request == first.request


def test_the_leader_does_not_re_time_its_move_nor_one_that_started(cell, clock, follower,
                                                                   leader):
    """Only the follower yields, and only a move that has not started yet."""
    _sent(_target(leader, ACROSS['scara_left'], stamp=11.0))
    assert _hear(leader, 'scara_right/1', 10.5,
                 _move(cell.follower, OUT['scara_right'], ACROSS['scara_right'])) == []
    _sent(_target(follower, [3.0, 1.0, 0.3]))
    clock.t = 10.2  # started
    assert _hear(follower, 'scara_left/1', 10.3,
                 _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'])) == []


def test_the_bridges_word_on_the_other_arm_corrects_what_is_heard(cell, clock, follower):
    """A leader move the bridge refused no longer binds the follower."""
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)
    _hear(follower, 'scara_left/1', 10.0, leader_move)
    assert follower.on_other_execution('refused', 'scara_left/1') == []
    assert _sent(_target(follower, ACROSS['scara_right'])).plan.delay == 0.0


def test_every_sent_move_keeps_the_margin_from_the_other_arms_commitment(cell, clock, follower):
    """The follower's delayed move and the leader's heard one never come within the margin."""
    leader_move = _move(cell.leader, OUT['scara_left'], ACROSS['scara_left'], back=True)
    _hear(follower, 'scara_left/1', 10.0, leader_move)
    move = _sent(_target(follower, ACROSS['scara_right']))
    t = np.arange(10.0, move.plan.end, 0.01)
    theirs = follower.other_motion.motion(10.0).at(t)
    mine = move.plan.timeline.at(t)
    gaps = [arm_distance(cell.follower, a, cell.leader, b) for a, b in zip(mine, theirs)]
    assert min(gaps) >= follower.settings.margin - 1e-3


# --- settings ------------------------------------------------------------------------------------
@pytest.mark.parametrize('overrides, message', [
    ({'mode': 'diagonal'}, "mode must be one of ('line', 'joint', 'line_or_joint')"),
    ({'planning_lead': 0.0}, 'planning_lead must be > 0, got 0.0'),
    ({'max_wait': -1.0}, 'max_wait must be > 0, got -1.0'),
])
def test_settings_refuse_an_unknown_mode_or_a_time_that_is_not_positive(cell, overrides,
                                                                        message):
    """The settings are checked when made, with the reason."""
    with pytest.raises(ValueError, match=message.replace('(', r'\(').replace(')', r'\)')):
        _settings(cell, **overrides)


def test_new_settings_take_effect_on_the_next_request(cell, clock, leader):
    """Settings replaced while it runs: the next move uses the new lead."""
    leader.settings = _settings(cell, planning_lead=0.5)
    assert _sent(_target(leader, [3.0, -1.0, 0.3])).plan.start == pytest.approx(10.5)
