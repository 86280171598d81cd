"""The job's request protocol alone (no job, no ROS): moves and grips asked, answered, timed."""
import numpy as np
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.kinematics import ik
from scara_collab.core.lanes import (GripCommand, Lane, LaneProtocol, MoveCommand, PlanMemo)
from scara_collab.core.mirror import mirror_joints, mirror_point
from scara_collab.core.planning import plan_path
from scara_collab.core.sorting import drop_point

HOME = np.array([0.0, 1.5708, 0.0])


def protocol(cell, mirrored=False, **overrides):
    """Return ``(protocol, lane)``: one lane of the leader (both arms if ``mirrored``)."""
    settings = JobSettings.from_config(cell, dict(load_config('automation'), **overrides),
                                       'mirrored' if mirrored else 'single')
    robots = (cell.leader.name, cell.follower.name) if mirrored else (cell.leader.name,)
    lane = Lane(cell.leader.name, robots)
    logs = []
    proto = LaneProtocol(cell, settings,
                         PlanMemo(lambda robot, q0, target: plan_path(
                             cell.arm(robot), q0, target, mode='line_or_joint')),
                         lambda level, text: logs.append((level, text)))
    proto.logs = logs
    for arm, q in zip(cell.arms, (HOME, mirror_joints(HOME))):
        proto.measured(arm.name, q)
    return proto, lane


def target(cell):
    """Return a reachable point of the leader: above its first bin."""
    return drop_point(cell, cell.leader.name, cell.item_classes[0], 0.1)


def test_a_move_is_a_command_with_a_fresh_request_and_the_jobs_plan(cell):
    """A move: the lane enters the phase, the request id is its start (ns), unique per arm."""
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 1.0, 0.0)
    assert isinstance(cmd, MoveCommand) and not cmd.mirrored and cmd.purpose == 'to_park'
    assert cmd.request == 1_000_000_000 and cmd.start == pytest.approx(1.0)
    assert lane.phase == 'to_park' and lane.moves[lane.robot].state == 'asked'
    np.testing.assert_allclose(cmd.plan.q[0], HOME, atol=1e-9)  # the job's plan, from here
    np.testing.assert_allclose(cmd.plan.p[-1], cmd.target, atol=1e-9)
    again = proto.open(lane, 'to_park', target(cell), 1.0, 0.0)  # the same start: the next id
    assert again.request == cmd.request + 1
    late = proto.open(lane, 'to_park', target(cell), 0.0, 2.0)  # a start in the past: now
    assert late.start > 2.0
    once = proto.open_once(cell.follower.name, target(cell), 1.0, 'park')
    assert once.request == 1_000_000_000 and lane.phase == 'to_park'


def test_a_move_ends_in_one_event_arrived_or_failed(cell):
    """Planned, accepted and finished: arrived; refused: failed with the reason."""
    proto, lane = protocol(cell)
    assert proto.advance(lane, 0.0) == ([], None)  # idle: nothing to follow
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    timed = proto.on_planner([lane], lane.robot, cmd.request, 'planned', 0.1, 1.0)
    assert timed is lane.moves[lane.robot] and (timed.start, timed.end) == (0.1, 1.0)
    waiting = proto.on_planner([lane], lane.robot, cmd.request, 'waiting', None, None)
    assert waiting is timed and (waiting.state, waiting.start) == ('waiting', None)
    assert proto.advance(lane, 0.5) == ([], None)  # waiting: within its deadline
    proto.on_planner([lane], lane.robot, cmd.request, 'planned', 0.6, 1.5)
    proto.on_execution([lane], lane.robot, cmd.request, 'accepted', 0.6, 1.5)
    proto.on_execution([lane], lane.robot, cmd.request, 'finished', None, None)
    sent, event = proto.advance(lane, 1.5)
    assert sent == [] and event.kind == 'arrived' and event.lane is lane

    cmd = proto.open(lane, 'to_park', target(cell), 2.0, 1.6)
    proto.on_execution([lane], lane.robot, cmd.request - 1, 'refused', None, None, 'an old one')
    assert proto.advance(lane, 1.7) == ([], None)  # not about this move: ignored
    proto.on_planner([lane], lane.robot, cmd.request, 'refused', None, None, 'unreachable')
    _, event = proto.advance(lane, 1.8)
    assert event.kind == 'failed' and event.why == f'{lane.robot} move refused: unreachable'


def test_a_move_at_its_end_with_the_tool_there_has_arrived_without_the_bridges_word(cell):
    """A lost ``finished``: the end time passed and the tool is at the target: arrived."""
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    proto.on_planner([lane], lane.robot, cmd.request, 'planned', 0.1, 1.0)
    assert proto.advance(lane, 1.0) == ([], None)  # the tool is not there yet
    proto.measured(lane.robot, ik(cell.leader, cmd.target, q_current=HOME).q)
    assert proto.advance(lane, 1.01)[1].kind == 'arrived'
    # not there within arrive_timeout of the end: failed
    cmd = proto.open(lane, 'to_park', [1.5, -1.0, 0.4], 1.1, 1.05)
    proto.on_planner([lane], lane.robot, cmd.request, 'planned', 1.1, 2.0)
    assert proto.advance(lane, 2.0 + proto.settings.arrive_timeout - 0.01) == ([], None)
    _, event = proto.advance(lane, 2.0 + proto.settings.arrive_timeout + 0.01)
    assert event.kind == 'failed' and 'did not arrive' in event.why


def test_an_accepted_move_arrives_at_its_end_whenever_the_bridges_finished_comes(cell):
    """The bridge's ``finished`` says no more than that the accepted end has passed.

    So the lane arrives at the first tick at or after that end, with the tool still short of
    the target, whether ``finished`` came before that tick or comes a tick later (messages on
    two topics, delivered in either order): the run's next step does not depend on it.
    """
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    proto.on_planner([lane], lane.robot, cmd.request, 'planned', 0.1, 1.0)
    assert proto.advance(lane, 1.0) == ([], None)  # planned only: the bridge may start it late
    proto.on_execution([lane], lane.robot, cmd.request, 'accepted', 0.12, 1.02)
    assert proto.advance(lane, 1.0) == ([], None)  # before its end
    assert proto.advance(lane, 1.02)[1].kind == 'arrived'  # its end: no finished, not there


def test_a_lost_answer_is_asked_again_with_the_same_request_then_fails(cell):
    """No planner answer: the same request again after ``answer_timeout``, then failed."""
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    timeout = proto.settings.answer_timeout
    assert proto.advance(lane, timeout * 0.5) == ([], None)
    t = 0.0
    for k in range(proto.settings.answer_retries):
        t += timeout + 0.01
        sent, event = proto.advance(lane, t)
        assert event is None and [(c.request, c.plan) for c in sent] == [(cmd.request, cmd.plan)]
    _, event = proto.advance(lane, t + timeout + 0.01)
    assert event.kind == 'failed' and 'no answer from the' in event.why
    assert proto.retries == proto.settings.answer_retries
    assert sum('asking again' in text for _, text in proto.logs) == proto.retries


def test_a_late_answer_lengthens_the_next_wait(cell):
    """The time a planner took to answer is added to ``answer_timeout`` from then on."""
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    proto.now = 0.3
    proto.on_planner([lane], lane.robot, cmd.request, 'queued', None, None)
    assert proto.answer_lag.worst == pytest.approx(0.3)
    cmd = proto.open(lane, 'to_park', target(cell), 1.0, 1.0)
    timeout = proto.settings.answer_timeout
    assert proto.advance(lane, 1.0 + timeout + 0.1) == ([], None)
    assert proto.advance(lane, 1.0 + timeout + 0.31)[0][0].request == cmd.request


def test_late_starts_of_its_own_moves_push_the_next_as_soon_as_possible_start(cell):
    """What the job assumes comes from what it measures: the bridge's late starts.

    Only its own open moves count (a stale status or another request's does not); the typical
    lateness is added, so a one-off spike does not move the aim.
    """
    proto, lane = protocol(cell)
    lead = proto.settings.leads.move
    assert proto.time.asap(1.0, lane.mirrored) == pytest.approx(1.0 + lead)  # nothing more
    for k in range(5):
        cmd = proto.open(lane, 'to_park', target(cell), proto.time.asap(k, lane.mirrored), k)
        proto.on_execution([lane], lane.robot, cmd.request + 7, 'accepted', k + 1.0, k + 2.0,
                           stamp=k + 0.5)
        proto.on_execution([lane], lane.robot, cmd.request, 'accepted', k + 0.1, k + 2.0,
                           stamp=k + 0.1 - (0.04 if k != 2 else 0.9))
    late = proto.time.late
    assert late.typical == pytest.approx(0.04) and late.worst == pytest.approx(0.9)
    assert proto.time.asap(10.0, lane.mirrored) == pytest.approx(10.0 + lead + 0.04)


def test_a_move_not_planned_by_its_deadline_fails_and_says_what_it_waited_for(cell):
    """Queued or waiting for longer than ``move_timeout`` (``carry_timeout`` holding): failed."""
    proto, lane = protocol(cell)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    proto.on_planner([lane], lane.robot, cmd.request, 'waiting', None, None, 'the other arm')
    limit = proto.settings.move_timeout
    assert proto.advance(lane, limit - 0.01) == ([], None)
    _, event = proto.advance(lane, limit + 0.01)
    assert event.kind == 'failed' and event.why.startswith(f'no plan from the {lane.robot}')
    lane.holding = True  # holding an item: it waits carry_timeout
    cmd = proto.open(lane, 'to_bin', target(cell), 10.0, 10.0)
    proto.on_planner([lane], lane.robot, cmd.request, 'queued', None, None)
    assert proto.advance(lane, 10.0 + limit + 0.01) == ([], None)
    assert proto.advance(lane, 10.0 + proto.settings.carry_timeout + 0.01)[1].kind == 'failed'


def test_grips_are_asked_again_and_any_attempts_answer_counts(cell):
    """A gripper call with no answer is made again with a new token; any answer counts."""
    proto, lane = protocol(cell)
    calls = proto.grips.ask(lane, True, 0.0)
    assert lane.phase == 'grasping' and [(c.robot, c.grasp) for c in calls] == \
        [(lane.robot, True)] and isinstance(calls[0], GripCommand)
    sent, event = proto.advance(lane, proto.settings.grip_timeout + 0.01)
    assert event is None and len(sent) == 1 and sent[0].token != calls[0].token
    proto.now = proto.settings.grip_timeout + 0.05
    # the first call's answer
    proto.grips.on_response([lane], calls[0].token, True, 'grasped (slow)', proto.now)
    assert proto.grips.lag.worst == pytest.approx(proto.settings.grip_timeout + 0.05)
    sent, event = proto.advance(lane, 0.4)
    assert sent == [] and event.kind == 'gripped' and lane.grips[lane.robot].ok
    # no answer at all: bounded calls, then the grip is over, failed
    proto.grips.ask(lane, False, 1.0)
    t = 1.0
    for _ in range(proto.settings.grip_retries + 1):
        t += proto.settings.grip_timeout + proto.grips.lag.worst + 0.01
        sent, event = proto.advance(lane, t)
    assert event.kind == 'gripped' and lane.grips[lane.robot].ok is False
    assert 'no answer after' in lane.grips[lane.robot].message


def test_a_bridge_event_confirms_a_grip_whose_answer_was_lost(cell):
    """``grasped`` while grasping (or ``released`` while releasing) answers the grip."""
    proto, lane = protocol(cell)
    proto.grips.ask(lane, True, 0.0)
    proto.grips.confirm([lane], 'released', lane.robot)  # not what the lane waits for
    assert proto.advance(lane, 0.01) == ([], None)
    proto.grips.confirm([lane], 'grasped', lane.robot)
    assert proto.advance(lane, 0.02)[1].kind == 'gripped'
    assert lane.grips[lane.robot].message == 'grasped event'


def test_a_mirrored_lane_moves_and_grips_both_arms_under_one_request(cell):
    """One request for both arms; arrived when both have; a grip per arm; asked a lead ahead."""
    proto, lane = protocol(cell, mirrored=True)
    lead, foll = cell.leader.name, cell.follower.name
    assert lane.mirrored and proto.time.asap(1.0, lane.mirrored) == pytest.approx(
        1.0 + proto.settings.leads.pair)
    cmd = proto.open(lane, 'to_park', target(cell), 0.1, 0.0)
    assert cmd.mirrored and set(lane.moves) == {lead, foll}
    np.testing.assert_allclose(proto.target_of(lane, foll),
                               mirror_point(cell.leader, cell.follower, cmd.target))
    for robot in (lead, foll):
        proto.on_planner([lane], robot, cmd.request, 'planned', 0.1, 1.0)
    proto.on_execution([lane], lead, cmd.request, 'finished', None, None)
    assert proto.advance(lane, 1.0) == ([], None)  # the follower has not arrived
    proto.on_execution([lane], foll, cmd.request, 'finished', None, None)
    assert proto.advance(lane, 1.02)[1].kind == 'arrived'
    assert sorted(c.robot for c in proto.grips.ask(lane, True, 1.1)) == sorted([lead, foll])


def test_a_move_is_planned_once_per_tick_and_a_refusal_remembered(cell):
    """The plan memo: the same move is planned once until it forgets; refusals repeat."""
    calls = []

    def plan(robot, q0, target):
        calls.append((robot, tuple(q0), tuple(target)))
        if target[0] > 100.0:
            raise ValueError('unreachable: beyond the outer reach')
        return plan_path(cell.arm(robot), q0, target, mode='line_or_joint')

    memo = PlanMemo(plan)
    robot = cell.leader.name
    first = memo(robot, HOME, target(cell))
    assert memo(robot, HOME.copy(), np.array(target(cell))) is first
    assert len(calls) == 1
    for _ in range(2):
        with pytest.raises(ValueError, match='outer reach'):
            memo(robot, HOME, [200.0, 0.0, 0.3])
    assert len(calls) == 2
    memo(robot, HOME + [0.1, 0.0, 0.0], target(cell))  # another start: another plan
    assert len(calls) == 3
    memo.forget()
    assert memo(robot, HOME, target(cell)) is not first
    assert len(calls) == 4
