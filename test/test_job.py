"""The sorting job's state machine alone (no ROS): deadlines, lost, late and duplicated answers."""
import numpy as np
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.job import (GripCommand, items_per_minute, JobSettings, MoveCommand,
                                   SortingJob)
from scara_collab.core.kinematics import ik
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.planning import plan_path
from scara_collab.core.sorting import drop_point, SeenItem

HOME = np.array([0.0, 1.5708, 0.0])


def make_job(cell, mode='collaborative', plan=None, people=None, **overrides):
    """Return a SortingJob on ``cell`` with the automation config (``overrides`` on top).

    :param plan: the job's plan function (default: the planners' line-or-joint planning).
    :param people: the protective separation's numbers (a cell with a safety scanner).
    """
    cfg = dict(load_config('automation'), **overrides)
    settings = JobSettings.from_config(cell, cfg, mode)

    def planned(robot, q0, target):
        return plan_path(cell.arm(robot), q0, target, mode='line_or_joint')
    plan = plan or planned

    logs = []
    job = SortingJob(cell, settings, plan, lambda level, text: logs.append((level, text)),
                     people=people)
    job.logs = logs
    for arm, q in zip(cell.arms, (HOME, mirror_joints(HOME))):
        job.on_arm_state(arm.name, q)
    job.start(0.0)
    return job


def item_on_belt(cell, item_id=1, x=1.2, y=-0.2, stamp=0.0, cls=None):
    """Return an item resting on the belt at ``(x, y)``, seen at ``stamp``."""
    z = cell.belt.top_z + cell.item_size / 2
    return SeenItem(item_id, cls or cell.item_classes[0], np.array([x, y, z]), stamp)


def moves(cmds):
    """Return the move commands among ``cmds``."""
    return [c for c in cmds if isinstance(c, MoveCommand)]


def grips(cmds):
    """Return the gripper commands among ``cmds``."""
    return [c for c in cmds if isinstance(c, GripCommand)]


def first_pick(cell, job, t=0.0):
    """Offer one item to the leader; return the pick MoveCommand."""
    job.on_items([item_on_belt(cell)])
    out = moves(job.tick(t))
    pick = [m for m in out if m.purpose == 'to_item']
    assert pick, out
    return pick[0]


def arrive(cell, job, cmd, t_end, robot=None):
    """Tell the job the move ``cmd`` ran and ended at ``t_end`` with the tool at the target."""
    robot = robot or cmd.robot
    job.on_planner(robot, cmd.request, 'planned', cmd.start, t_end)
    job.on_execution(robot, cmd.request, 'accepted', cmd.start, t_end)
    job.on_arm_state(robot, ik(cell.arm(robot), cmd.target, q_current=job.q[robot]).q)
    job.on_execution(robot, cmd.request, 'finished', None, None)


def at_the_item(cell, **overrides):
    """Return ``(job, pick move, t)``: the leader arrived at t with item 1 under its tool."""
    job = make_job(cell, **overrides)
    pick = first_pick(cell, job)
    t = pick.start + 1.0
    job.on_items([SeenItem(1, cell.item_classes[0], np.r_[pick.target[:2],
                                                          cell.belt.top_z + 0.05], t)])
    arrive(cell, job, pick, t)
    return job, pick, t


def test_items_per_minute_has_one_definition():
    """The items-per-minute figure is one function, and zero for no time."""
    assert items_per_minute(30, 60.0) == 30.0
    assert items_per_minute(5, 0.0) == 0.0


def test_a_lost_planner_answer_is_asked_again_with_the_same_request(cell):
    """A planner answer that never comes is asked for again under the same request id."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    s = job.settings
    assert not moves(job.tick(s.answer_timeout * 0.5))  # not yet
    again = moves(job.tick(s.answer_timeout + 0.01))
    assert [m.request for m in again] == [pick.request]  # same id: the planner is idempotent
    t = s.answer_timeout + 0.01
    for _ in range(s.answer_retries):
        t += s.answer_timeout + 0.01
        job.tick(t)
    assert job.decisions.give_ups == 1 and 'no answer' in job.decisions.last_give_up
    assert job.phases()[pick.robot] == 'to_park'  # it parks clear of the belt
    assert job.protocol.retries == s.answer_retries


def test_duplicated_and_stale_answers_change_nothing(cell):
    """Answers that come twice, or for an old request, change nothing."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    job.on_planner(pick.robot, pick.request, 'planned', pick.start, pick.start + 1.0)
    job.on_planner(pick.robot, pick.request, 'planned', pick.start, pick.start + 1.0)
    job.on_planner(pick.robot, pick.request - 5, 'refused', None, None, 'old request')
    job.on_execution(pick.robot, pick.request - 5, 'refused', None, None, 'old')
    job.on_grip(999, False, 'a token nobody asked for')
    assert job.phases()[pick.robot] == 'to_item'
    assert not moves(job.tick(pick.start + 0.5))  # waiting for the end, nothing re-sent
    assert job.decisions.give_ups == 0


def test_every_waiting_phase_has_a_deadline(cell):
    """A move that never arrives, or is never planned, is given up at its deadline."""
    # planned but never arrives (trajectory lost, tool not at the target): arrive_timeout
    job = make_job(cell)
    pick = first_pick(cell, job)
    job.on_planner(pick.robot, pick.request, 'planned', pick.start, pick.start + 1.0)
    job.tick(pick.start + 1.0 + job.settings.arrive_timeout * 0.5)
    assert job.decisions.give_ups == 0
    job.tick(pick.start + 1.0 + job.settings.arrive_timeout + 0.01)
    assert job.decisions.give_ups == 1 and 'did not arrive' in job.decisions.last_give_up

    # queued / waiting in the planner for longer than move_timeout
    job = make_job(cell)
    pick = first_pick(cell, job)
    job.on_planner(pick.robot, pick.request, 'waiting', None, None, 'blocked')
    job.tick(job.settings.move_timeout - 0.1)
    assert job.decisions.give_ups == 0
    job.tick(job.settings.move_timeout + 0.1)
    assert job.decisions.give_ups == 1 and 'no plan' in job.decisions.last_give_up


def test_lost_gripper_answers_are_asked_again_then_fail(cell):
    """A gripper call with no answer is made again (bounded), then the grasp has failed."""
    job, pick, t = at_the_item(cell)
    out = grips(job.tick(t))
    assert len(out) == 1 and out[0].grasp
    first = out[0].token
    out = grips(job.tick(t + job.settings.grip_timeout + 0.01))  # no answer: ask again, new token
    assert len(out) == 1 and out[0].token != first and out[0].grasp
    job.on_grip(out[0].token, True, 'already holds item 1')  # idempotent server: success
    nxt = moves(job.tick(t + 0.5))
    assert nxt[0].purpose == 'to_bin'  # nothing else on the belt: straight to the bin
    job.on_grip(first, True, 'late answer to the first call')  # that grip is over: ignored
    assert job.phases()[pick.robot] == 'to_bin'

    # no answer at all: bounded retries, then the grasp failed and the arm is free again
    job, pick, t = at_the_item(cell)
    job.tick(t)
    for k in range(job.settings.grip_retries + 1):
        t += job.settings.grip_timeout + 0.01
        job.tick(t)
    assert job.phases()[pick.robot] == 'idle' and job.lanes[0].failures == {1: 1}


def test_a_slow_gripper_answer_counts_and_the_timeout_grows_with_what_is_measured(cell):
    """The answer to an earlier attempt is the answer (the gripper is idempotent).

    Answers that take longer than ``grip_timeout`` (real time, a busy machine) make the next
    grips wait that much longer before asking again, and aim the tool where the item will be
    when the grasp takes hold: the latency is measured, not assumed.
    """
    from scara_collab.core.lanes import GRASP_LEAD
    job, pick, t = at_the_item(cell)
    first = grips(job.tick(t))[0].token
    slow = job.settings.grip_timeout + 0.1
    again = grips(job.tick(t + job.settings.grip_timeout + 0.02))  # asked again meanwhile
    assert again and again[0].token != first
    job.tick(t + slow)
    job.on_grip(first, True, 'grasped (slow)')  # the first call's answer, late
    nxt = moves(job.tick(t + slow + 0.02))
    assert nxt and nxt[0].purpose == 'to_bin'
    assert job.protocol.grips.lag.worst == pytest.approx(slow)
    # a job that measured it meets the item where it will be when the grasp takes hold
    # (that far downstream), and waits grip_timeout plus it before asking again
    job2 = make_job(cell)
    job2.protocol.grips.lag.add(slow)
    pick2 = first_pick(cell, job2)
    # (the meeting time moves a little too: a move to another point takes another time)
    lead = job2.protocol.grips.lead
    assert lead == pytest.approx(min(slow, GRASP_LEAD))  # a typical answer time, bounded
    assert pick2.target[0] - pick.target[0] == pytest.approx(cell.belt.speed * lead, abs=0.015)
    t2 = pick2.start + 1.0
    upstream = pick2.target[0] - cell.belt.speed * lead  # the item, as the tool arrives
    job2.on_items([SeenItem(1, cell.item_classes[0], np.r_[upstream, pick2.target[1],
                                                           cell.belt.top_z + 0.05], t2)])
    arrive(cell, job2, pick2, t2)
    assert grips(job2.tick(t2))
    assert not grips(job2.tick(t2 + job2.settings.grip_timeout + 0.05))
    assert grips(job2.tick(t2 + job2.settings.grip_timeout + slow + 0.02))


def test_a_slow_planner_answer_lengthens_the_wait_before_asking_again(cell):
    """The time a planner took to answer is added to ``answer_timeout`` for what follows."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    late = 0.4 * job.settings.answer_timeout
    job.tick(late)
    job.on_planner(pick.robot, pick.request, 'planned', pick.start + late, pick.start + 1.0)
    assert job.protocol.answer_lag.worst == pytest.approx(late)
    job2 = make_job(cell)
    job2.protocol.answer_lag.add(late)
    pick2 = first_pick(cell, job2)
    assert not moves(job2.tick(job2.settings.answer_timeout + 0.02))  # not yet: it measured late
    assert moves(job2.tick(job2.settings.answer_timeout + late + 0.02))[0].request == pick2.request


def test_a_grasped_event_confirms_a_grasp_whose_answer_was_lost(cell):
    """A grasped event from the bridge stands in for a lost gripper answer."""
    job, pick, t = at_the_item(cell)
    job.tick(t)
    job.on_item_event('grasped', 1, pick.robot)
    assert moves(job.tick(t + 0.02))[0].purpose == 'to_bin'


def test_a_grasped_item_is_lifted_only_when_it_would_sweep_the_belt(cell):
    """A grasped item is lifted first only when carrying it straight would sweep the belt."""
    for neighbours, expected in (([], 'to_bin'), ([(0.0, 0.0)], 'lift'),
                                 ([(0.0, 0.35)], 'to_bin')):
        job = make_job(cell)
        pick = first_pick(cell, job)
        t = pick.start + 1.0
        z = cell.belt.top_z + cell.item_size / 2
        here = np.r_[pick.target[:2], z]
        # another item where the held item passes on its way to the bin (or well clear of it)
        drop = drop_point(cell, pick.robot, cell.item_classes[0], job.settings.drop_clearance)
        path = job.plan(pick.robot, ik(cell.leader, pick.target, q_current=job.q[pick.robot]).q,
                        drop)
        k = len(path.t) // 8  # early in the move, while the held item is still low
        seen = [SeenItem(1, cell.item_classes[0], here, t)]
        for n, (dx, dy) in enumerate(neighbours):
            x = path.p[k, 0] - cell.belt.speed * (job.settings.leads.decision + path.t[k]) + dx
            seen.append(SeenItem(10 + n, cell.item_classes[1],
                                 np.r_[x, path.p[k, 1] + dy, z], t))
        job.on_items(seen)
        arrive(cell, job, pick, t)
        job.on_grip(grips(job.tick(t))[0].token, True, 'grasped')
        nxt = moves(job.tick(t + 0.02))[0]
        assert nxt.purpose == expected, (neighbours, nxt.purpose)
        if expected == 'lift':
            assert nxt.target[2] == pytest.approx(job.settings.carry_z)
            assert np.allclose(nxt.target[:2], pick.target[:2])  # straight up
            # lifted, it is carried at that height all the way to the bin: a line down to the
            # drop point would bring it back to the tops of the items it was lifted over
            arrive(cell, job, nxt, t + 0.5)
            carry = moves(job.tick(t + 0.52))[0]
            assert carry.purpose == 'to_bin' and carry.target[2] >= job.settings.carry_z
            assert np.min(carry.plan.p[:, 2]) >= job.settings.carry_z - 1e-6
            assert np.allclose(carry.target[:2], drop[:2])


def test_the_sweep_check_covers_a_start_as_late_as_measured(cell):
    """An item just upstream of the carry path is clear on time, swept if the move is late."""
    from scara_collab.core.sorting import carry_sweeps
    size, spare, z = cell.item_size, 0.02, cell.belt.top_z + cell.item_size / 2
    path = np.array([[2.0, 0.0, 0.25], [2.0, 0.0, 0.25]])  # the held item low over x = 2 m
    times = np.array([1.0, 1.5])
    gap = 0.1  # m more than the closest the check allows, upstream at 1.5 s
    x = 2.0 - size - spare - gap - cell.belt.speed * 1.5  # centres size + spare + gap apart
    upstream = [SeenItem(5, cell.item_classes[0], np.array([x, 0.0, z]), 0.0)]
    pick_z = path[0, 2]
    assert not carry_sweeps(cell, path, times, upstream, pick_z, spare)
    late = 1.2 * gap / cell.belt.speed
    assert carry_sweeps(cell, path, times, upstream, pick_z, spare, late=late)
    assert not carry_sweeps(cell, path, times, upstream, pick_z, spare, late=0.8 * late / 1.2)


def test_an_arm_holding_an_item_retries_its_bin_instead_of_dropping_it(cell):
    """An arm holding an item tries its bin again when a move fails, never drops it off the bin."""
    job, pick, t = at_the_item(cell, lift_after_grasp=False)
    g = grips(job.tick(t))[0]
    job.on_grip(g.token, True, 'grasped')
    to_bin = moves(job.tick(t + 0.02))[0]
    assert to_bin.purpose == 'to_bin'
    job.on_planner(to_bin.robot, to_bin.request, 'refused', None, None, 'blocked too long')
    again = job.tick(t + 0.04)
    assert [m.purpose for m in moves(again)] == ['to_bin'] and not grips(again)
    assert moves(again)[0].request > to_bin.request


def test_mirrored_moves_are_one_request_for_both_arms(cell):
    """In mirrored mode one request moves both arms, and the mirror image item is claimed."""
    job = make_job(cell, 'mirrored')
    lead, foll = cell.leader.name, cell.follower.name
    job.on_items([item_on_belt(cell, 1, y=-0.2), item_on_belt(cell, 2, y=0.2)])
    pick = moves(job.tick(0.0))[0]
    assert pick.mirrored and pick.robot == lead
    assert job.board.claimed == {1: lead, 2: foll}
    # one hop more to both planners (the replication manager): asked a pair lead further ahead
    assert pick.start >= job.settings.leads.decision + job.settings.leads.pair - 1e-9
    assert first_pick(cell, make_job(cell)).start < \
        job.settings.leads.decision + job.settings.leads.pair
    t = pick.start + 1.0
    arrive(cell, job, pick, t)  # only the leader arrived: the lane waits for the follower
    job.tick(t)
    assert job.phases()[lead] == 'to_item'
    from scara_collab.core.mirror import mirror_point
    mirrored = MoveCommand(foll, mirror_point(cell.leader, cell.follower, pick.target),
                           pick.request, True, 'to_item')
    arrive(cell, job, mirrored, t, foll)
    job.on_items([SeenItem(1, cell.item_classes[0], np.r_[pick.target[:2],
                                                          cell.belt.top_z + 0.05], t)])
    out = grips(job.tick(t))
    assert sorted(g.robot for g in out) == sorted([lead, foll])


def test_mirrored_picks_keep_the_pair_apart(cell):
    """Mirrored picks near the centre line are aimed off it, so the pair keeps its margin."""
    job = make_job(cell, 'mirrored')
    job.on_items([item_on_belt(cell, 1, y=-0.06), item_on_belt(cell, 2, y=0.06)])
    pick = moves(job.tick(0.0))[0]
    assert pick.target[1] == pytest.approx(-job.settings.pair_offset)  # aimed off the centre line


def test_estop_pauses_and_stop_is_idempotent(cell):
    """The e-stop pauses the job, and stopping twice is the same as once."""
    job = make_job(cell)
    job.on_estop(True)
    job.on_items([item_on_belt(cell)])
    assert job.tick(0.0) == []
    job.on_estop(False)
    assert moves(job.tick(0.1))
    assert job.stop() is True and job.stop() is False
    assert job.start(1.0) is True and job.start(1.0) is False


def test_an_arm_in_the_way_parks_and_a_deadlock_is_broken_by_the_follower(cell):
    """An idle arm in the way parks; when both arms wait for each other the follower gives way."""
    lead, foll = cell.leader.name, cell.follower.name
    # the leader waits for the right arm, which stands idle in the way: the right arm parks
    job = make_job(cell)
    pick = first_pick(cell, job)
    assert job.phases() == {lead: 'to_item', foll: 'idle'}
    job.on_items([])  # nothing for the right arm to take meanwhile
    job.on_planner(lead, pick.request, 'waiting', None, None, 'scara_right blocks it')
    job.tick(0.1)
    assert job.phases()[foll] == 'idle'  # not yet: unblock_after
    out = moves(job.tick(0.1 + job.settings.unblock_after + 0.01))
    assert job.phases()[foll] == 'to_park' and [m.robot for m in out] == [foll]

    # both wait for each other: the follower's lane gives way (it parks), the leader stays
    job = make_job(cell)
    job.on_items([item_on_belt(cell, 1, y=-0.2), item_on_belt(cell, 2, x=1.0, y=0.2)])
    out = moves(job.tick(0.0))  # the follower's move goes out once the leader's is answered
    assert [m.robot for m in out] == [lead]
    job.on_planner(lead, out[0].request, 'waiting', None, None, 'the other arm blocks it')
    out = moves(job.tick(0.02))
    assert [m.robot for m in out] == [foll]
    job.on_planner(foll, out[0].request, 'waiting', None, None, 'the other arm blocks it')
    job.tick(job.settings.unblock_after + 0.1)
    assert job.phases() == {lead: 'to_item', foll: 'to_park'}
    assert 'scara_right gives way' in job.decisions.last_give_up


def test_two_arms_holding_items_and_blocking_each_other_untangle(cell):
    """Untangle two arms that hold items and wait for each other's bin moves.

    Seen in the hour-long soak at t=3087 s: 21 s stuck, then items let go where the arms
    stood. Neither may put its item down, so the follower backs out on its own side first,
    then goes to its bin.
    """
    from scara_collab.core.lanes import MoveTrack
    lead, foll = cell.leader.name, cell.follower.name
    job = make_job(cell)
    job.on_items([])
    for robot, tool in ((lead, [1.34, -0.26, 0.34]), (foll, [0.83, 0.05, 0.34])):
        job.on_arm_state(robot, ik(cell.arm(robot), tool).unwrap())
    for k, lane in enumerate(job.lanes):
        lane.phase, lane.holding, lane.item = 'to_bin', True, item_on_belt(cell, k + 1)
        lane.target = drop_point(cell, lane.robot, lane.item.cls, job.settings.drop_clearance)
        lane.request = 1000 + k
        lane.moves = {lane.robot: MoveTrack(state='waiting', since=0.0)}
    out = moves(job.tick(job.settings.unblock_after + 0.1))
    assert [m.robot for m in out] == [foll] and out[0].purpose == 'via'
    assert out[0].target[1] >= cell.belt.centre_y + 0.6  # out on the right arm's side
    assert job.phases() == {lead: 'to_bin', foll: 'via'}
    assert job.decisions.give_ups == 0  # nothing given up, nothing put down
    lane = next(la for la in job.lanes if la.robot == foll)
    assert lane.holding and [p for p, _ in lane.route] == ['to_bin']
    # at the waypoint it goes on to its bin with the item
    job.on_arm_state(foll, ik(cell.follower, out[0].target).unwrap())
    job.on_planner(foll, out[0].request, 'finished', None, None)
    job.on_execution(foll, out[0].request, 'finished', None, None)
    nxt = moves(job.tick(job.settings.unblock_after + 1.0))
    assert [m.purpose for m in nxt if m.robot == foll] == ['to_bin']


def test_a_retreat_that_did_not_clear_the_way_is_followed_by_one_further_out(cell):
    """Back out further, then the other arm, instead of backing out to the same place again.

    Seen in a soak (t = 480-525 s, 16 items missed): the follower, holding an item, backed
    out to y = 0.60 m, was still in the way of the leader's bin move, and "backed out" to
    y = 0.60 again every second while both arms waited.
    """
    from scara_collab.core.lanes import MoveTrack
    lead, foll = cell.leader.name, cell.follower.name
    job = make_job(cell)
    job.on_items([])
    job.on_arm_state(lead, ik(cell.arm(lead), [1.34, -0.26, 0.34]).unwrap())
    for k, lane in enumerate(job.lanes):
        lane.phase, lane.holding, lane.item = 'to_bin', True, item_on_belt(cell, k + 1)
        lane.target = drop_point(cell, lane.robot, lane.item.cls, job.settings.drop_clearance)
        lane.request = 1000 + k
        lane.moves = {lane.robot: MoveTrack(state='waiting', since=0.0)}
    ys = []
    for step in range(4):
        t = job.settings.unblock_after + 0.1 + step
        for lane in job.lanes:  # still both waiting after whatever came before
            lane.phase = 'to_bin'
            lane.moves = {lane.robot: MoveTrack(state='waiting', since=t - 0.6)}
        out = [m for m in moves(job.tick(t)) if m.purpose == 'via']
        if not out:
            break
        ys.append((out[0].robot, round(float(out[0].target[1]), 2)))
        arm = cell.arm(out[0].robot)  # it got there
        job.on_arm_state(out[0].robot, ik(arm, out[0].target).unwrap())
    foll_ys = [abs(y) for r, y in ys if r == foll]
    assert foll_ys and foll_ys == sorted(set(foll_ys)), ys  # each one further out
    assert len(ys) >= 2


def test_an_arm_waiting_for_the_other_arms_work_re_aims_instead_of_giving_up(cell):
    """Keep the target current while the other arm works next to the item, then meet it.

    Seen in-process (seed 8, t=180.7 s): the leader went to an item 0.26 m from the
    follower's, so the follower's planner waited until the leader lifted. The job gave up
    after ``move_timeout`` (3 s), 60 ms before the way was clear. Now it asks again for the
    item where the belt has carried it, and gives up only when the item has got away.
    """
    from scara_collab.core.lanes import MoveTrack
    lead, foll = cell.leader.name, cell.follower.name
    job = make_job(cell)
    item = item_on_belt(cell, 97, x=1.12, y=0.01, stamp=0.0)
    job.on_items([item])
    lane = next(la for la in job.lanes if la.robot == foll)
    busy = next(la for la in job.lanes if la.robot == lead)
    busy.phase, busy.item, busy.request = 'to_item', item_on_belt(cell, 98, 1.07, 0.27), 5
    busy.target = busy.item.position
    busy.moves = {lead: MoveTrack(state='accepted', start=0.0, end=3.0)}
    job.board.claimed[97] = foll
    assert job.chase(foll, item, 0.0)
    first = lane.request
    job.on_planner(foll, first, 'waiting', None, None, f'{lead} blocks it')
    assert moves(job.tick(job.settings.unblock_after - 0.1)) == []  # waiting is normal at first
    t = job.settings.unblock_after + 0.1
    job.on_items([SeenItem(97, item.cls, item.position + [cell.belt.speed * t, 0, 0], t)])
    again = moves(job.tick(t))
    assert [(m.robot, m.purpose) for m in again] == [(foll, 'to_item')]
    assert again[0].request != first
    assert again[0].target[0] > item.position[0] + cell.belt.speed * t - 1e-9  # downstream
    assert job.decisions.give_ups == 0 and job.board.claimed[97] == foll
    assert any('re-aims at item 97' in text for _, text in job.logs)
    # the leader stays in the way: the follower re-aims every unblock_after while its
    # planner waits, and gives up once the item has got away (never on move_timeout)
    busy.moves[lead].end = 60.0
    sent = [again[0]]
    while job.decisions.give_ups == 0 and t < 30.0:
        job.on_planner(foll, sent[-1].request, 'waiting', None, None, f'{lead} blocks it')
        t += 0.1
        job.on_items([SeenItem(97, item.cls, item.position + [cell.belt.speed * t, 0, 0], t)])
        sent += [m for m in moves(job.tick(t)) if m.purpose == 'to_item']
    assert job.decisions.give_ups == 1 and 'got away' in job.decisions.last_give_up, job.logs
    assert len(sent) > 3 and all(b.target[0] > a.target[0] for a, b in zip(sent, sent[1:]))
    assert 97 not in job.board.claimed


def test_an_arm_takes_no_item_the_other_arms_booked_move_would_make_it_wait_for(cell):
    """The shared zone booked in time: a chase is scheduled against the other arm's move.

    At saturation (an item a second) most give-ups were "got away while it waited for the
    other arm": the follower went for an item beside the leader's, its planner held it back
    for the leader, and the item left. Now the job plans the leader's timed move as its
    planner did and schedules the follower's chase against it with the planners' rule: an
    item it would wait for is met later, or another item is taken.
    """
    from scara_collab.core import planning
    lead, foll = cell.leader, cell.follower
    near, ours = item_on_belt(cell, 98, x=1.07, y=0.27), item_on_belt(cell, 97, x=1.12, y=0.01)

    def follower_chase(booked: bool):
        job = make_job(cell)
        job.on_items([near, ours])
        cmd = job.chase(lead.name, near, 0.0)[-1]
        track = job.belt.heard[lead.name]  # the leader's commitments, its booking among them
        if booked:  # the leader's planner timed it: the job now knows the motion
            job.on_planner(lead.name, cmd.request, 'planned', cmd.start, cmd.start + 2.0)
        else:  # blind: as if the job had not planned the leader's intercept itself
            track.booked = None
        assert (track.booked is not None) == booked
        took = job.chase(foll.name, ours, 0.0)
        return job, track, job.lane(foll.name), took

    job, _, lane, took = follower_chase(booked=False)
    assert took  # blind to the leader's motion: it goes at once ...
    plan = job.plan(foll.name, job.q[foll.name], lane.target)
    first = took[-1]
    job, track, lane, took = follower_chase(booked=True)
    leader_motion = track.booked.timeline
    # ... into a move the planners would hold back for the leader (the follower yields)
    held = planning.schedule(foll, plan, first.start, lead, leader_motion,
                             job.settings.pair_margin, leader=False)
    tolerance = 0.5 * job.settings.grasp_reach / cell.belt.speed
    assert held is None or held.delay > tolerance
    if took:  # booked: met later, when the way is clear, never into a wait
        cmd = took[-1]
        assert cmd.start > first.start
        traj = job.plan(foll.name, job.q[foll.name], cmd.target)
        later = planning.schedule(foll, traj, cmd.start, lead, leader_motion,
                                  job.settings.pair_margin, leader=False)
        assert later is not None and later.delay <= tolerance
    else:
        assert lane.phase == 'idle' and lane.item is None


def test_the_booking_is_the_trajectory_the_planner_published(cell):
    """The other arm's booked motion is the planner's own trajectory, not planned again.

    Heard before or after the planner's ``planned`` status, it books the arm by the
    committed-motion model's rules, at the start the bridge reports. Until then a move is
    booked as the job planned it when it asked (a chase: its intercept), so the other lane
    does not take the arm for standing still meanwhile; a move the job could not plan then is
    planned once it is timed. A trajectory the job did not ask for commits the arm as well;
    in single mode nothing is booked.
    """
    from scara_collab.core import planning
    lead = cell.leader
    calls, refuse = [], []

    def counted(robot, q0, target):  # the job's plans, counted; refused while ``refuse``
        calls.append(robot)
        if refuse:
            raise ValueError('no plan now')
        return plan_path(cell.arm(robot), q0, target, mode='line_or_joint')

    for published_first in (True, False):
        job = make_job(cell, plan=counted)
        job.on_items([item_on_belt(cell, 98, x=1.07, y=0.27)])
        cmd = job.chase(lead.name, job.board.items[98], 0.0)[-1]
        intended = job.belt.committed(lead.name, 0.0, job.q)  # asked, not answered: the job's
        assert intended.start == pytest.approx(cmd.start) and intended.end > cmd.start
        traj = job.plan(lead.name, job.q[lead.name], cmd.target)
        job.plan.forget()  # from here on, planning the move again would be counted
        calls[:] = []
        move_id = f'{lead.name}/{cmd.request}'
        published = cmd.start + 0.05, traj.t, traj.q + 1e-3  # the planner's, not the job's
        if published_first:
            job.on_trajectory(lead.name, move_id, cmd.request, *published)
        job.on_planner(lead.name, cmd.request, 'planned', cmd.start + 0.05,
                       cmd.start + 0.05 + traj.duration)
        if not published_first:
            job.on_trajectory(lead.name, move_id, cmd.request, *published)
        booked = job.belt.committed(lead.name, 0.0, job.q)
        np.testing.assert_allclose(booked.q[1:], published[2])
        for on in (job.on_execution, lambda *a: job.on_arm_status(lead.name, 'accepted',
                                                                  move_id, cmd.start + 0.25)):
            on(lead.name, cmd.request, 'accepted', cmd.start + 0.25,
               cmd.start + 0.25 + traj.duration)
        assert job.belt.committed(lead.name, 0.0, job.q).end == \
            pytest.approx(cmd.start + 0.25 + traj.duration)
        assert calls == []  # never planned again
    raw = make_job(cell)
    raw.on_trajectory(lead.name, 'by hand', None, 0.0, traj.t, traj.q)  # not asked for
    assert raw.belt.committed(lead.name, 0.0, raw.q).end == pytest.approx(traj.duration)
    lost = make_job(cell, plan=counted)  # a park move: booked as the job plans it when it asks
    cmd = lost.park(lead.name, 0.0)[-1]
    assert cmd.purpose == 'to_park' and lost.belt.committed(lead.name, 0.0, lost.q).end > cmd.start
    refuse.append(True)
    lost.plan.forget()
    cmd = lost.park(lead.name, 1.0)[-1]  # the job cannot plan it: not booked until timed ...
    assert lost.belt.heard[lead.name].booked.timeline is None
    assert lost.belt.committed(lead.name, 1.0, lost.q).end == 1.0  # asked, unplanned: it holds
    refuse.clear()
    lost.plan.forget()
    lost.on_planner(lead.name, cmd.request, 'planned', cmd.start, cmd.start + 2.0)
    assert isinstance(lost.belt.heard[lead.name].booked.timeline, planning.Timeline)  # planned
    single = make_job(cell, mode='single')
    single.on_items([item_on_belt(cell, 98, x=1.07, y=0.27)])
    cmd = single.chase(lead.name, single.board.items[98], 0.0)[-1]
    single.on_trajectory(lead.name, f'{lead.name}/{cmd.request}', cmd.request, *published)
    assert not hasattr(single.belt, 'heard')  # one arm: nothing to book


def test_a_chase_asked_in_the_same_tick_is_respected_before_its_answer(cell):
    """Both lanes decide in one tick: the second respects the first's asked, unanswered move.

    The job books its own intercept of the leader's chase until the planner answers, so the
    follower's chase beside it is met later or left, exactly as against the planned move.
    """
    from scara_collab.core import planning
    lead, foll = cell.leader, cell.follower
    near, ours = item_on_belt(cell, 98, x=1.07, y=0.27), item_on_belt(cell, 97, x=1.12, y=0.01)
    job = make_job(cell)
    job.on_items([near, ours])
    busy = job.lane(lead.name)
    assert job.chase(lead.name, near, 0.0)
    intended = job.belt.committed(lead.name, 0.0, job.q)
    assert busy.moves[lead.name].state == 'asked' and intended.end > intended.start
    lane = job.lane(foll.name)
    tolerance = 0.5 * job.settings.grasp_reach / cell.belt.speed
    took = job.chase(foll.name, ours, 0.0)
    if took:
        cmd = took[-1]
        traj = job.plan(foll.name, job.q[foll.name], cmd.target)
        timed = planning.schedule(foll, traj, cmd.start, lead, intended, job.settings.pair_margin,
                                  leader=False)
        assert timed is not None and timed.delay <= tolerance
    else:
        assert lane.phase == 'idle' and 97 not in job.board.claimed


def test_the_followers_move_goes_out_after_the_leaders_planner_has_answered(cell):
    """Both lanes ask in one tick: the follower's offer is held for the leader's answer.

    Its planner schedules against the leader's trajectories; sent in the same tick, the offer
    could reach it before or after the leader's new trajectory (docs/realtime.md, *Repeatable
    runs*). Held, it goes out, unchanged, in the first tick after the leader's planner answers, or
    after ``answer_timeout`` if that answer is lost.
    """
    lead, foll = cell.leader, cell.follower
    for lost in (False, True):
        job = make_job(cell)
        job.on_items([item_on_belt(cell, 1, x=1.2, y=-0.2), item_on_belt(cell, 2, x=1.2, y=0.2)])
        out = moves(job.tick(0.0))
        assert [c.robot for c in out] == [lead.name]
        held = next(la for la in job.lanes if la.robot == foll.name)
        assert held.phase == 'to_item' and held.moves[foll.name].state == 'asked'
        assert moves(job.tick(0.02)) == []  # the leader has not answered yet
        if not lost:
            job.on_planner(lead.name, out[0].request, 'planned', out[0].start, out[0].start + 1)
            late = moves(job.tick(0.04))
        else:
            assert moves(job.tick(job.settings.answer_timeout - 0.01)) == []
            late = [c for c in moves(job.tick(job.settings.answer_timeout))
                    if c.robot == foll.name]
        assert [(c.robot, c.request) for c in late] == [(foll.name, held.request)]
    single = make_job(cell, mode='single')
    single.on_items([item_on_belt(cell, 1, x=1.2, y=-0.2)])
    # one lane: nothing held (the unused arm's park goes out beside the leader's pick)
    assert {c.robot for c in moves(single.tick(0.0))} == {lead.name, foll.name}


def test_an_item_about_to_leave_reach_is_chased_even_if_the_arm_must_wait(cell):
    """Deferring is for items with time to spare: else both arms may defer one until it is gone.

    In an hour's soak one item rode the whole belt while both arms took younger ones: each
    deferred it for the other's booked move. An item with less than ``URGENT_SLACK`` left in
    the arm's reach is chased at once (the planner holds the arm back if it must).
    """
    from scara_collab.core import planning, sharing
    from scara_collab.core.sorting import reach_span
    lead, foll = cell.leader, cell.follower
    job = make_job(cell)
    near = item_on_belt(cell, 98, x=2.5, y=0.0)
    ours = item_on_belt(cell, 97, x=2.7, y=0.05)  # beside it, downstream
    exit_x = reach_span(foll, ours.position[1], job.settings.pick_z, 0.0, cell.belt.x_end)[1]
    job.on_items([near, ours])
    busy = job.lane(lead.name)
    first = job.chase(lead.name, near, 0.0)[-1]
    job.on_planner(lead.name, busy.request, 'planned', first.start, 3.0)
    booked = job.belt.heard[lead.name].booked
    assert booked.timeline is not None
    lane = job.lane(foll.name)
    took = job.chase(foll.name, ours, 0.0)  # urgent: taken at once, the leader in the way
    assert took
    cmd = took[-1]
    plan = job.plan(foll.name, job.q[foll.name], cmd.target)
    held = planning.schedule(foll, plan, cmd.start, lead, booked.timeline,
                             job.settings.pair_margin, leader=False)
    tolerance = 0.5 * job.settings.grasp_reach / cell.belt.speed
    assert held is None or held.delay > tolerance  # it will wait: deferring would have skipped
    assert (exit_x - ours.position[0]) / cell.belt.speed < sharing.URGENT_SLACK
    # the same item with time to spare is deferred (met later or left for another)
    sharing.URGENT_SLACK, saved = 0.0, sharing.URGENT_SLACK
    try:
        lane.phase, lane.item = 'idle', None
        later = job.chase(foll.name, ours, 0.0)
        if later:
            assert later[-1].start > cmd.start
    finally:
        sharing.URGENT_SLACK = saved


def test_an_urgent_chase_is_timed_around_the_other_arms_booked_move(cell):
    """An urgent item is not deferred, but met where it will be when the way is clear.

    In an hour's soak an arm chased an urgent item on the time it could have left, the
    planner held it back for the other arm's move, the tool arrived 4.7 cm behind the item at
    the end of its reach and the item was lost. Here the follower's booked move stands on the
    leader's way to an urgent item for a while: the leader's chase starts when the way is
    clear, aimed at where the item will be then; if the item would have left the leader's reach
    by then, the leader does not claim it (the other arm may still save it).
    """
    from scara_collab.core import planning
    from scara_collab.core.lanes import MoveTrack
    from scara_collab.core.sharing import URGENT_SLACK
    from scara_collab.core.sorting import intercept, time_in_reach
    lead, foll = cell.leader, cell.follower
    tolerance = 0.5 * load_config('automation')['grasp_reach'] / cell.belt.speed

    def chase(leaves_at):
        job = make_job(cell)
        item = item_on_belt(cell, 97, x=2.6, y=0.1)
        job.on_items([item])
        blind = intercept(cell, lead, job.q[lead.name], item, job.settings.leads.decision,
                          job.settings.pick_z, lambda q, p: job.plan(lead.name, q, p))
        stay = ik(foll, blind.target + [0.0, 0.12, 0.0]).q  # on the meeting point
        away = ik(foll, np.array([3.3, 1.6, job.settings.pick_z])).q
        motion = planning.Timeline(np.array([0.0, leaves_at, leaves_at + 0.5]),
                                   np.array([stay, stay, away]))
        busy = next(la for la in job.lanes if la.robot == foll.name)
        busy.phase, busy.request = 'to_item', 5
        busy.moves = {foll.name: MoveTrack('planned', start=0.0, end=motion.end)}
        job.belt.heard[foll.name].book(5, motion)  # booked as asked, its planner's word
        job.on_arm_state(foll.name, stay)
        assert time_in_reach(cell, lead, item.position, job.settings.pick_z) < URGENT_SLACK
        took = job.chase(lead.name, item, 0.0)
        return job, blind, motion, job.lane(lead.name), took

    job, blind, motion, lane, took = chase(leaves_at=2.0)
    assert took
    cmd = took[-1]
    assert cmd.start > blind.start + tolerance  # waits for the way to clear ...
    moved = cell.belt.speed * (cmd.start - blind.start)
    assert cmd.target[0] - blind.target[0] == pytest.approx(moved, abs=0.03)  # ... aimed later
    traj = job.plan(lead.name, job.q[lead.name], cmd.target)
    held = planning.schedule(lead, traj, cmd.start, foll, motion, job.settings.pair_margin,
                             leader=False)
    assert held is not None and held.delay <= tolerance  # no further wait: it meets the item
    job, blind, motion, lane, took = chase(leaves_at=3.5)
    assert not took and lane.phase == 'idle' and 97 not in job.board.claimed  # gone by then


def test_items_are_taken_shortest_cycle_first_unless_urgent_and_savable(cell):
    """Urgent items the arm can save go first, most urgent first; the rest by their cycle.

    The left arm waits above its red bin (upstream, x = 0.6). A red and a blue item side by
    side upstream, both with time to spare: the red one makes the shorter cycle (its bin is
    near) and comes first, though the blue one is further downstream (more urgent). One blue
    item about to leave reach stays in front of both. With more urgent items than the arm can
    save (the feed is faster than the arm), every candidate goes by its cycle.
    """
    from scara_collab.core import job_decisions, sharing, sorting
    job = make_job(cell)
    lane = job.lanes[0]
    arm = cell.arm(lane.robot)
    job.on_arm_state(lane.robot, ik(arm, sorting.drop_point(cell, lane.robot, 'red', 0.1)).q)
    z, start = job.settings.pick_z, job.settings.leads.decision

    def spare(it):
        return sorting.time_in_reach(cell, arm, sorting.predict(cell, it, start), z)

    def cost(it):
        return sorting.cycle_bound(cell, arm, job.q[lane.robot], it, start, z,
                                   job.settings.drop_clearance)

    def ranked(items):
        urgency = sorting.order_candidates(cell, arm, items, start, z, True, False, groups=True)
        return ([it.id for _, it in urgency],
                [it.id for _, it in sorting.rank_by_cycle(
                    cell, arm, job.q[lane.robot], urgency, start, z, job.settings.drop_clearance,
                    sharing.URGENT_SLACK, job_decisions.SAVABLE)])

    red = item_on_belt(cell, 1, x=0.7, y=-0.2, cls='red')
    blue = item_on_belt(cell, 2, x=0.9, y=-0.2, cls='blue')
    late = item_on_belt(cell, 3, x=3.3, y=-0.2, cls='blue')
    assert min(spare(red), spare(blue)) >= sharing.URGENT_SLACK > spare(late)
    assert cost(red) < cost(blue)
    assert ranked([red, blue, late]) == ([3, 2, 1], [3, 1, 2])

    crowd = [item_on_belt(cell, 10 + k, x=x, y=-0.2, cls=c)
             for k, (x, c) in enumerate(((3.3, 'red'), (3.1, 'blue'), (2.9, 'red'),
                                         (2.7, 'blue')))]
    assert all(spare(it) < sharing.URGENT_SLACK for it in crowd)
    assert len(crowd) > job_decisions.SAVABLE
    urgency, order = ranked(crowd + [red])
    assert urgency == [10, 11, 12, 13, 1]
    by_cost = sorted(crowd + [red], key=cost)
    assert order == [it.id for it in by_cost] and order != urgency


def test_every_item_in_reach_is_ranked_not_only_the_most_urgent(cell):
    """The cheapest cycle wins even behind many more urgent items (none of them urgent).

    Seven blue items ride ahead of one red item; the left arm waits above its red bin. The
    red item, the least urgent, makes the shortest cycle and comes first: the job ranks every
    item in reach, not only the few most urgent, whose cycles may all be longer.
    """
    from scara_collab.core import job_decisions, sharing, sorting
    job = make_job(cell)
    lane = job.lanes[0]
    arm = cell.arm(lane.robot)
    job.on_arm_state(lane.robot, ik(arm, sorting.drop_point(cell, lane.robot, 'red', 0.1)).q)
    z, start = job.settings.pick_z, job.settings.leads.decision
    blues = [item_on_belt(cell, 1 + k, x=0.85 + 0.1 * k, y=-0.2, cls='blue') for k in range(7)]
    red = item_on_belt(cell, 20, x=0.7, y=-0.2, cls='red')
    items = blues + [red]
    assert all(sorting.time_in_reach(cell, arm, sorting.predict(cell, it, start), z)
               >= sharing.URGENT_SLACK for it in items)
    urgency = sorting.order_candidates(cell, arm, items, start, z, True, False, groups=True)
    assert [it.id for _, it in urgency][-1] == red.id  # the least urgent
    order = sorting.rank_by_cycle(cell, arm, job.q[lane.robot], urgency, start, z,
                                  job.settings.drop_clearance, sharing.URGENT_SLACK,
                                  job_decisions.SAVABLE)
    assert order[0][1].id == red.id
    assert sorted(it.id for _, it in order) == sorted(it.id for it in items)


def test_a_missed_item_says_what_the_job_last_did_with_it(cell):
    """The job logs why an item got away: its last note (ranked, chased, given up) or none."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    job.on_item_event('missed', 1, '')
    assert ('warn', f'item 1 missed; last: {pick.robot} chased it at t=0.00 s') in job.logs
    job.on_item_event('missed', 7, '')
    assert ('warn', 'item 7 missed; last: never a candidate of either arm') in job.logs
    job.on_item_event('sorted', 7, pick.robot)  # notes are dropped with the item
    assert sum('missed' in text for _, text in job.logs) == 2


def test_one_arms_moves_carry_the_jobs_plan_so_the_planner_need_not_plan_again(cell):
    """Every one-arm move goes with the job's plan of it: from the arm's state to the target.

    The chase's plan is the intercept's own trajectory (planned once, to choose the item); a
    re-sent request carries the same plan; a mirrored pair's carries the leader's (the
    replication manager mirrors it for the follower).
    """
    job = make_job(cell, 'single')
    pick = first_pick(cell, job)
    assert pick.plan is not None and pick.plan.t[0] == 0.0
    np.testing.assert_allclose(pick.plan.q[0], HOME, atol=1e-9)
    np.testing.assert_allclose(pick.plan.p[-1], pick.target, atol=1e-9)
    assert pick.plan.qd.shape == pick.plan.qdd.shape == pick.plan.q.shape
    again = moves(job.tick(job.settings.answer_timeout + 0.01))
    assert [m.request for m in again] == [pick.request] and again[0].plan is pick.plan
    # grasped at the item: the move on (lift or to the bin) is planned from where the arm is
    job, pick, t = at_the_item(cell, mode='single')
    grip = grips(job.tick(t))[0]
    job.on_grip(grip.token, True)
    on = moves(job.tick(t + 0.01))[0]
    assert on.purpose in ('lift', 'to_bin') and on.plan is not None
    np.testing.assert_allclose(on.plan.q[0], job.q[pick.robot], atol=1e-9)
    np.testing.assert_allclose(on.plan.p[-1], on.target, atol=1e-9)
    mirrored = make_job(cell, 'mirrored')
    mirrored.on_items([item_on_belt(cell, 1, y=-0.2), item_on_belt(cell, 2, y=0.2)])
    pick = moves(mirrored.tick(0.0))[0]
    assert pick.mirrored and pick.robot == cell.leader.name
    np.testing.assert_allclose(pick.plan.q[0], HOME, atol=1e-9)
    np.testing.assert_allclose(pick.plan.p[-1], pick.target, atol=1e-9)


def test_an_item_that_slips_is_no_longer_its_lanes_and_free_for_either_arm(cell):
    """A slipped item: its claim goes, the lane carries nothing on, the note says why."""
    job, pick, t = at_the_item(cell)
    lane = job.lane(pick.robot)
    job.on_grip(grips(job.tick(t))[0].token, True, 'grasped')
    job.tick(t + 0.02)
    assert lane.holding and job.board.claimed == {1: pick.robot}
    job.on_item_event('slipped', 1, pick.robot)
    assert not lane.holding and job.board.claimed == {}
    assert job.decisions.notes.close(1).startswith(f'it slipped from the {pick.robot} gripper')
