"""The job's belt sharing alone (no job, no ROS): bookings, held moves, unblocking, chases."""
import numpy as np
import pytest

from scara_collab.core import planning, sorting
from scara_collab.core.config import load_config
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.kinematics import ik
from scara_collab.core.lanes import Lane, LaneProtocol, MoveTrack, PlanMemo
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.planning import plan_path
from scara_collab.core.sharing import SharedBelt, SoloBelt

HOME = np.array([0.0, 1.5708, 0.0])


def shared(cell, solo=False):
    """Return ``(belt, protocol, leader lane, follower lane)`` on the collaborative settings.

    The protocol's ``lanes`` are both lanes (a test's own note: the job owns them).
    """
    settings = JobSettings.from_config(cell, load_config('automation'), 'collaborative')
    lanes = [Lane(cell.leader.name, (cell.leader.name,)),
             Lane(cell.follower.name, (cell.follower.name,))]
    plan = PlanMemo(lambda robot, q0, target: plan_path(cell.arm(robot), q0, target,
                                                        mode='line_or_joint'))
    proto = LaneProtocol(cell, settings, plan)
    proto.lanes = lanes
    for arm, q in zip(cell.arms, (HOME, mirror_joints(HOME))):
        proto.measured(arm.name, q)
    belt = (SoloBelt if solo else SharedBelt)(cell, settings, plan)
    return belt, proto, lanes[0], lanes[1]


def park_point(cell, robot):
    """Return the point above ``robot``'s first bin."""
    return sorting.drop_point(cell, robot, cell.item_classes[0], 0.1)


def item(cell, item_id, x, y):
    """Return an item resting on the belt at ``(x, y)``, seen at t = 0."""
    return sorting.SeenItem(item_id, cell.item_classes[0],
                            np.array([x, y, cell.belt.top_z + cell.item_size / 2]), 0.0)


def waiting(lane, since=0.0, holding=False):
    """Put ``lane`` in a move its planner holds back for the other arm since ``since``."""
    lane.phase, lane.holding, lane.request = ('to_bin' if holding else 'to_item'), holding, 7
    lane.moves = {lane.robot: MoveTrack(state='waiting', since=since)}


def test_a_solo_belt_books_holds_and_unblocks_nothing(cell):
    """One lane: the commands go out as they are, a chase is not re-timed, nothing booked."""
    belt, proto, lead, foll = shared(cell, solo=True)
    out = [proto.open(foll, 'to_park', park_point(cell, foll.robot), 0.1, 0.0)]
    assert belt.in_turn(out, proto.lanes, 0.0) is out
    belt.book(foll)
    belt.on_trajectory(foll.robot, 'm', out[0].request, 0.0, np.array([0.0, 1.0]),
                       np.zeros((2, 3)), 0.0, proto.q)
    belt.on_status(foll.robot, 'accepted', 'm', 0.0, 0.0, proto.q)
    belt.answered(foll.robot, foll.moves[foll.robot], out[0].target, proto.q)
    belt.settle(foll)
    assert vars(belt) == {}  # nothing kept
    waiting(lead)
    waiting(foll)
    assert belt.blocked(proto.lanes, 10.0, proto.q) is None
    hit = object()
    assert belt.unhindered(lead, None, hit, 0.0, proto.q, 0.0) is hit


def test_a_move_is_booked_as_asked_then_as_the_arm_is_committed_to_it(cell):
    """Asked: the job's plan from the requested start; once heard, the committed-motion model's.

    The planner's trajectory, then the bridge's later start, then its end: the booking is
    what the model says the arm runs. A move timed while its trajectory was lost is the job's
    plan, shifted or planned from where the arm is.
    """
    belt, proto, lead, _ = shared(cell)
    cmd = proto.open(lead, 'to_park', park_point(cell, lead.robot), 0.5, 0.0)
    assert belt.committed(lead.robot, 0.0, proto.q).end == 0.0  # not booked yet: it holds
    belt.book(lead)
    asked = belt.committed(lead.robot, 0.0, proto.q)
    assert asked.start == pytest.approx(0.5)
    assert asked.end == pytest.approx(0.5 + cmd.plan.duration)
    q = cmd.plan.q + 1e-3  # the planner's own, published, to start at 0.6
    belt.on_trajectory(lead.robot, 'L/1', cmd.request, 0.6, cmd.plan.t, q, 0.05, proto.q)
    assert belt.heard[lead.robot].booked.heard
    np.testing.assert_allclose(belt.committed(lead.robot, 0.1, proto.q).q[1:], q)
    timed = proto.on_execution(proto.lanes, lead.robot, cmd.request, 'accepted', 0.8,
                               0.8 + cmd.plan.duration)
    belt.answered(lead.robot, timed, cmd.target, proto.q)  # heard: the model books it
    belt.on_status(lead.robot, 'accepted', 'L/1', 0.8, 0.1, proto.q)
    booked = belt.committed(lead.robot, 0.1, proto.q)
    assert booked.start == 0.1 and booked.end == pytest.approx(0.8 + cmd.plan.duration)
    np.testing.assert_allclose(booked.at(0.8 + cmd.plan.t[3]), q[3])
    belt.on_status(lead.robot, 'finished', 'L/1', None, 0.8 + cmd.plan.duration, proto.q)
    late = 1.0 + cmd.plan.duration
    assert belt.committed(lead.robot, late, proto.q).end == late  # over: the arm holds
    # a move timed before any trajectory came is planned from where the arm is
    cmd = proto.open(lead, 'to_park', [1.5, -1.0, 0.4], 2.0, 1.0)
    lead.plan = None  # the job could not plan it when it asked
    belt.book(lead)
    assert belt.committed(lead.robot, 1.0, proto.q).end == 1.0  # unknown: it holds
    timed = proto.on_planner(proto.lanes, lead.robot, cmd.request, 'planned', 2.0, 3.0)
    belt.answered(lead.robot, timed, cmd.target, proto.q)
    np.testing.assert_allclose(belt.committed(lead.robot, 1.0, proto.q).t, 2.0 + cmd.plan.t)
    waits = proto.on_planner(proto.lanes, lead.robot, cmd.request, 'waiting', None, None)
    belt.answered(lead.robot, waits, cmd.target, proto.q)  # not in hand: it does not count
    assert belt.committed(lead.robot, 1.0, proto.q).end == 1.0
    belt.settle(lead)
    assert belt.heard[lead.robot].booked is None


def test_a_trajectory_the_job_did_not_ask_for_commits_the_arm_too(cell):
    """A raw command (or a planner's hold) books the arm as the bridge will run it."""
    belt, proto, lead, _ = shared(cell)
    q0 = proto.q[lead.robot]
    there = planning.Timeline(np.array([0.0, 1.0]), np.vstack([q0, q0 + [0.3, 0.0, 0.0]]))
    belt.on_trajectory(lead.robot, '', None, 0.0, there.t, there.q, 2.0, proto.q)
    raw = belt.committed(lead.robot, 2.0, proto.q)
    assert (raw.start, raw.end) == (2.0, 3.0)
    np.testing.assert_allclose(raw.q[-1], q0 + [0.3, 0.0, 0.0])
    belt.on_status(lead.robot, 'held', '', None, 2.5, proto.q)  # the bridge held the arm
    assert belt.committed(lead.robot, 2.5, proto.q).end == 2.5


def test_the_followers_moves_wait_for_the_leaders_planner(cell):
    """Held while the leader's move awaits its first answer; released after it or the timeout."""
    belt, proto, lead, foll = shared(cell)
    first = proto.open(lead, 'to_park', park_point(cell, lead.robot), 0.1, 0.0)
    second = proto.open(foll, 'to_park', park_point(cell, foll.robot), 0.1, 0.0)
    assert belt.in_turn([first, second], proto.lanes, 0.0) == [first]
    assert belt.in_turn([], proto.lanes, 0.02) == []
    proto.on_planner(proto.lanes, lead.robot, first.request, 'planned', 0.1, 1.0)
    assert belt.in_turn([], proto.lanes, 0.04) == [second]
    assert belt.in_turn([], proto.lanes, 0.06) == []  # sent once
    again = proto.open(lead, 'to_park', [1.5, -1.0, 0.4], 2.0, 1.0)
    belt.in_turn([again, second], proto.lanes, 1.0)
    timeout = load_config('automation')['answer_timeout']
    assert belt.in_turn([], proto.lanes, 1.0 + timeout - 0.01) == []
    assert belt.in_turn([], proto.lanes, 1.0 + timeout) == [second]  # the answer was lost
    belt.in_turn([second], proto.lanes, 1.0 + timeout)
    belt.drop_held()  # a stop: nothing held survives it
    proto.on_planner(proto.lanes, lead.robot, again.request, 'planned', 2.0, 3.0)
    assert belt.in_turn([], proto.lanes, 1.0 + timeout + 0.02) == []


def test_an_arm_that_waits_for_the_other_is_unblocked(cell):
    """Park an idle arm in the way; re-aim a waiting chase; the follower gives way."""
    belt, proto, lead, foll = shared(cell)
    after = load_config('automation')['unblock_after']
    waiting(lead)
    assert belt.blocked(proto.lanes, after - 0.01, proto.q) is None  # normal at first
    how = belt.blocked(proto.lanes, after + 0.01, proto.q)
    assert (how.action, how.lane, how.other) == ('park', foll, lead)
    foll.phase = 'to_bin'  # busy, not waiting: the leader re-aims at its item meanwhile
    how = belt.blocked(proto.lanes, after + 0.01, proto.q)
    assert (how.action, how.lane, how.other) == ('reaim', lead, foll)
    lead.holding = True  # an arm that holds an item has no item to re-aim at
    assert belt.blocked(proto.lanes, after + 0.01, proto.q) is None
    lead.holding = False
    waiting(foll)
    how = belt.blocked(proto.lanes, after + 0.01, proto.q)
    assert (how.action, how.lane) == ('give_way', foll) and how.why.endswith(
        f'{foll.robot} gives way')
    waiting(foll, holding=True)  # the one not holding an item gives way
    how = belt.blocked(proto.lanes, after + 0.01, proto.q)
    assert (how.action, how.lane) == ('give_way', lead)


def test_two_arms_holding_items_are_untangled_by_the_follower_backing_out(cell):
    """Both hold items and wait for each other: the follower backs out on its own side."""
    belt, proto, lead, foll = shared(cell)
    for robot, tool in ((lead.robot, [1.34, -0.26, 0.34]), (foll.robot, [0.83, 0.05, 0.34])):
        proto.measured(robot, ik(cell.arm(robot), tool).unwrap())
    waiting(lead, holding=True)
    waiting(foll, holding=True)
    how = belt.blocked(proto.lanes, 1.0, proto.q)
    assert (how.action, how.lane) == ('back_out', foll)
    assert how.via[1] >= cell.belt.centre_y + 0.6  # out on the right arm's side
    foll.phase = 'via'  # already backing out: the leader is next, if it can
    how = belt.blocked(proto.lanes, 1.0, proto.q)
    assert how is None or (how.action, how.lane) == ('back_out', lead)


def test_a_chase_is_timed_around_the_other_arms_booking(cell):
    """Unknown or out of the way, the other arm changes nothing; booked in the way, it does."""
    belt, proto, lead, foll = shared(cell)
    near, ours = item(cell, 98, 1.07, 0.27), item(cell, 97, 1.12, 0.01)
    settings = JobSettings.from_config(cell, load_config('automation'), 'collaborative')

    def hit_for(lane, it):
        return sorting.intercept(cell, cell.arm(lane.robot), proto.q[lane.robot], it,
                                 settings.leads.decision, settings.pick_z,
                                 lambda q, p: belt.plan(lane.robot, q, p))

    mine = hit_for(foll, ours)
    assert belt.unhindered(foll, ours, mine, 0.0, {foll.robot: proto.q[foll.robot]}, 0.0) is mine
    assert belt.unhindered(foll, ours, mine, 0.0, proto.q, 0.0) is mine  # the leader stands clear
    theirs = hit_for(lead, near)
    proto.open(lead, 'to_item', theirs.target, theirs.start, 0.0, theirs.traj)
    belt.book(lead)  # the leader goes for the item beside it first
    timed = belt.unhindered(foll, ours, mine, 0.0, proto.q, 0.0)
    assert timed is None or timed.start > mine.start
    if timed is not None:  # met later, when the way is clear
        held = planning.schedule(cell.follower, timed.traj, timed.start, cell.leader,
                                 belt.committed(lead.robot, 0.0, proto.q),
                                 settings.pair_margin, leader=False)
        assert held is not None and held.delay <= 0.5 * settings.grasp_reach / cell.belt.speed
