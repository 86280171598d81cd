"""The moves the sorting job asks (core/job_moves.py): asked and booked, intercepts, parking."""
import numpy as np
from test_job import item_on_belt, make_job

from scara_collab.core import sorting, ssm
from scara_collab.core.config import load_config
from scara_collab.core.job import MoveCommand
from scara_collab.core.job_moves import NEAR_AHEAD
from scara_collab.core.kinematics import ik
from scara_collab.core.lanes import GripCommand
from scara_collab.core.sorting import drop_point


def person(x, y, vx=0.0, vy=0.0):
    """Return a person as the separation monitor reports one (a column 0.25 m in radius)."""
    return ssm.Person(np.array([x, y]), np.array([vx, vy]), 0.25, 1.8)


def people_job(cell, persons):
    """Return a job of a cell with a safety scanner that sees ``persons`` at t = 0."""
    job = make_job(cell, people=ssm.SsmParams.from_config(load_config('people')))
    job.on_persons(persons, False, 0.0)
    return job


def test_a_park_move_goes_above_the_first_bin_and_is_booked(cell):
    """``to_park`` asks one move to the first bin's drop point and books it on the belt."""
    job = make_job(cell)
    moves, lane = job.moves, job.lane(cell.follower.name)
    out = moves.to_park(lane, 1.0)
    assert len(out) == 1 and isinstance(out[0], MoveCommand)
    cmd = out[0]
    park = drop_point(cell, lane.robot, cell.item_classes[0], job.settings.drop_clearance)
    assert cmd.robot == lane.robot and cmd.purpose == 'to_park'
    assert np.allclose(cmd.target, park) and cmd.start >= 1.0
    assert lane.phase == 'to_park'
    assert job.belt.committed(lane.robot, 1.0, job.q).end > 1.0  # the other lane sees it


def test_a_chase_meets_an_item_in_reach_and_refuses_one_out_of_reach(cell):
    """``meet`` asks a ``to_item`` move on the item's future path, or nothing."""
    job = make_job(cell)
    moves, lane = job.moves, job.lane(cell.leader.name)
    (cmd,) = moves.meet(lane, item_on_belt(cell, x=1.2, y=-0.2), 0.0)
    assert cmd.purpose == 'to_item' and lane.item.id == 1 and cmd.plan is not None
    assert cmd.start >= job.settings.leads.decision
    assert abs(cmd.target[1] - (-0.2)) < 1e-9 and cmd.target[0] > 1.2  # downstream of x
    beyond = item_on_belt(cell, item_id=2, x=cell.belt.x_end - 0.01, y=0.0)
    assert moves.meet(job.lane(cell.follower.name), beyond, 0.0) == []


def test_unused_arms_are_parked_off_the_belt(cell):
    """In ``single`` mode the follower no lane uses is sent to its first bin once."""
    job = make_job(cell, mode='single')
    out = [c for c in job.tick(0.0) if isinstance(c, MoveCommand)]
    parked = [c for c in out if c.robot == cell.follower.name]
    assert len(parked) == 1
    assert np.allclose(parked[0].target, drop_point(cell, cell.follower.name,
                                                    cell.item_classes[0],
                                                    job.settings.drop_clearance))
    assert not [c for c in job.tick(0.02) if getattr(c, 'robot', '') == cell.follower.name]


def test_a_meeting_where_a_walking_person_is_going_is_left_for_the_person(cell):
    """A person walking towards a meeting is weighed where they will be, not where they are.

    4 m upstream at 1.6 m/s, they would be beside the arm when it gets there: the meeting is
    left ('person'); the same person standing where they were seen is far enough away for the
    arm to take the item at speed.
    """
    item = item_on_belt(cell, x=0.0, y=-0.2)
    standing = people_job(cell, [person(-4.0, -0.9)])
    (cmd,) = standing.moves.meet(standing.lane(cell.leader.name), item, 0.0)
    assert cmd.purpose == 'to_item' and standing.moves.declined == ''
    walking = people_job(cell, [person(-4.0, -0.9, vx=1.6)])
    assert walking.moves.meet(walking.lane(cell.leader.name), item, 0.0) == []
    assert walking.moves.declined == 'person'


def test_a_person_walking_towards_an_arm_is_near_it_before_they_are_in_its_reach(cell):
    """A person beyond an arm's reach counts as near if their way leads into it (5 s ahead).

    Standing there, or walking away, they do not: the job weighs moves against the persons
    near only, and a move that has begun cannot be given up.
    """
    job = people_job(cell, [])
    arm = cell.leader
    params = job.moves.people
    reach = (arm.l1 + arm.l2 + ssm.true_separation_bound(arm, params) + params.intrusion
             + params.sensor_tolerance)
    base = arm.base[:2, 3]
    x = base[0] - reach - 0.25 - 2.0  # 2 m beyond the reach (0.25: the column's radius)
    assert 1.0 * NEAR_AHEAD > 2.0  # walking in at 1 m/s, they are in reach within it
    for vx, near in ((0.0, False), (-1.0, False), (1.0, True)):
        job.on_persons([person(x, base[1], vx=vx)], False, 0.0)
        assert bool(job.moves._near(arm)) is near, vx


def test_a_slowed_move_is_weighed_again_where_the_person_will_be_when_it_gets_there(cell):
    """A move slowed to s takes 1 / s as long: a person walking in has come closer by then.

    Weighed on its planned times, a meeting with a person 4.5 m upstream walking at 1.6 m/s
    would run at 0.76 of its speed; on the times it would then take, the person is beside the
    arm when it gets there, and it could not run at all. With nobody near, nothing changes.
    """
    arm = cell.leader
    job = people_job(cell, [])
    moves = job.moves
    hit = sorting.intercept(cell, arm, job.protocol.q[arm.name], item_on_belt(cell, x=0.0,
                                                                              y=-0.2),
                            0.0, job.settings.pick_z, lambda a, p: moves.plan(arm.name, a, p))
    traj = hit.traj
    k = np.linspace(0, len(traj.t) - 1, 5)[1:].round().astype(int)
    walker = [person(-4.5, -0.9, vx=1.6)]
    planned = ssm.allowed_along(arm, traj.q[k], traj.qd[k], walker, moves.people, ahead=traj.t[k])
    assert 0.3 < planned < 0.9
    assert moves._speed_along(arm, traj, 0.0, walker) == 0.0
    far = [person(-20.0, -0.9)]
    assert moves._speed_along(arm, traj, 0.0, far) == 1.0


def test_an_arm_parks_above_the_bin_it_can_reach_at_speed_when_a_person_is_near(cell):
    """Parking goes above the first bin; with a person near that bin, above the other one.

    The arm reaches the other one without the monitor slowing it as much.
    """
    clearance = make_job(cell).settings.drop_clearance
    first, other = (drop_point(cell, cell.follower.name, c, clearance)
                    for c in cell.item_classes[:2])
    alone = make_job(cell)
    (cmd,) = alone.moves.to_park(alone.lane(cell.follower.name), 1.0)
    assert np.allclose(cmd.target, first)
    near = people_job(cell, [person(0.5, -0.9)])
    (cmd,) = near.moves.to_park(near.lane(cell.follower.name), 1.0)
    assert np.allclose(cmd.target, other)


def test_a_meeting_not_begun_is_given_up_when_a_person_comes_near_it(cell):
    """A meeting asked with nobody near is weighed again when a person walks towards it.

    Given up before the arm has begun it, the arm parks instead.
    """
    job = people_job(cell, [])
    job.on_items([item_on_belt(cell, x=0.0, y=-0.2)])
    (pick,) = [c for c in job.tick(0.0) if isinstance(c, MoveCommand)]
    assert pick.purpose == 'to_item' and pick.robot == cell.leader.name
    job.on_persons([person(-4.0, -0.9)], False, 0.02)  # standing: the meeting stands
    assert not [c for c in job.tick(0.02) if isinstance(c, MoveCommand)]
    job.on_persons([person(-4.0, -0.9, vx=1.6)], False, 0.3)  # walking towards it
    (park,) = [c for c in job.tick(0.3) if isinstance(c, MoveCommand)]
    assert park.robot == cell.leader.name and park.purpose == 'to_park'
    assert any('a person came near the meeting' in text for _, text in job.logs)


def test_an_arm_kept_from_every_item_by_a_person_leaves_the_bin_next_to_them(cell):
    """Idle above its first bin with a person beside it, the arm parks above the other bin.

    From there it can meet items at speed; once there it stays.
    """
    robot = cell.follower.name
    clearance = make_job(cell).settings.drop_clearance
    first, other = (drop_point(cell, robot, c, clearance) for c in cell.item_classes[:2])
    job = people_job(cell, [person(0.0, 2.0)])
    lane = job.lane(robot)
    job.on_arm_state(robot, ik(cell.arm(robot), first).q)
    (cmd,) = job.moves.away_from_person(lane, 1.0)
    assert cmd.purpose == 'to_park' and np.allclose(cmd.target, other)
    job.moves.free(lane)
    job.on_arm_state(robot, ik(cell.arm(robot), other).q)
    assert job.moves.away_from_person(lane, 2.0) == []


def test_an_item_whose_bin_is_next_to_a_person_is_left_to_the_other_arm(cell):
    """The meeting and the carry to the bin are weighed as one cycle.

    A person stands beyond the leader's red bin, far from the belt: a red item downstream is
    met at speed but would be carried to the person, so it is left ('person'); a blue one,
    met at the same place, goes to the other bin, and is taken.
    """
    red, blue = cell.item_classes[:2]
    for cls, taken in ((red, False), (blue, True)):
        job = people_job(cell, [person(-0.5, -3.0)])
        out = job.moves.meet(job.lane(cell.leader.name),
                             item_on_belt(cell, x=2.5, y=-0.2, cls=cls), 0.0)
        assert bool(out) == taken
        assert job.moves.declined == ('' if taken else 'person')


def test_an_item_grasped_as_a_person_came_by_its_bin_goes_back_on_the_belt(cell):
    """Grasped with nobody near; a person beyond its bin by then: the arm lets it go there.

    It goes on along the belt (for the other arm, or this one once the person has left), and
    this arm takes it no sooner than any other item it failed; a blue item goes to its bin.
    """
    robot = cell.leader.name
    red, blue = cell.item_classes[:2]
    for cls in (red, blue):
        job = people_job(cell, [])
        lane = job.lane(robot)
        item = item_on_belt(cell, x=2.5, y=-0.2, cls=cls)
        job.on_items([item])
        (pick,) = [c for c in job.tick(0.0) if isinstance(c, MoveCommand)]
        job.on_arm_state(robot, ik(cell.arm(robot), pick.target).q)
        (grasp,) = job.protocol.grips.ask(lane, True, 2.0)
        job.on_grip(grasp.token, True, 'grasped')
        job.on_persons([person(-0.5, -3.0)], False, 2.0)
        out = job.tick(2.0)
        if cls == red:
            (release,) = [c for c in out if isinstance(c, GripCommand)]
            assert release.robot == robot and not release.grasp
            assert lane.phase == 'releasing' and lane.failures[item.id] == 1
            assert any('puts item 1 back on the belt' in text for _, text in job.logs)
        else:
            (carry,) = [c for c in out if isinstance(c, MoveCommand)]
            assert carry.purpose == 'to_bin'
