"""Planning decisions without ROS: timelines and the priority rule's schedule."""
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core.collision import arm_distance
from scara_collab.core.kinematics import ik
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path, schedule, Timeline
from scara_collab.core.sorting import drop_point


@pytest.fixture(scope='module')
def cell():
    """Return the cell model."""
    return load_cell()


def test_timeline_since_keeps_only_what_is_left():
    """A timeline cut at a time keeps only the motion still to come, interpolated at the cut."""
    tl = Timeline(np.array([1.0, 2.0, 3.0]), np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]))
    assert tl.since(0.5) is tl  # not started yet: all of it is still to come
    part = tl.since(1.5)
    assert_allclose(part.t, [1.5, 2.0, 3.0])
    assert_allclose(part.q, [[0.5, 0.5, 0.5], [1, 1, 1], [2, 2, 2]])
    assert_allclose(part.at(2.5), tl.at(2.5))
    done = tl.since(4.0)
    assert done.start == done.end == 4.0
    assert_allclose(done.q, [[2, 2, 2]])


def test_past_motion_of_the_other_arm_does_not_block_a_start(cell):
    """Both arms picked side by side; the right arm is leaving for its bin.

    Its move started next to where the left arm holds an item, so its *past* came within the
    margin of the left arm's pose. Checked whole, that past blocks every start of the left
    arm's bin move (both arms then waited for each other); from now on the left arm can go.
    """
    left, right = cell.leader, cell.follower
    margin = cell.safety_margin + 0.03
    z = 0.34
    q_left = ik(left, [1.24, -0.03, z]).q
    q_right0 = ik(right, [1.38, 0.06, z]).q
    assert arm_distance(left, q_left, right, q_right0) < margin  # they were that close
    away = plan_path(right, q_right0, drop_point(cell, right.name, cell.item_classes[0], 0.1),
                     mode='line_or_joint')
    theirs = Timeline.of(away, 10.0)
    now = 10.0 + 0.8 * away.duration
    assert arm_distance(left, q_left, right, theirs.at(now)) > margin  # ... and are apart now
    home = plan_path(left, q_left, drop_point(cell, left.name, cell.item_classes[0], 0.1),
                     mode='line_or_joint')
    assert schedule(left, home, now + 0.05, right, theirs, margin, leader=True) is None
    plan = schedule(left, home, now + 0.05, right, theirs.since(now), margin, leader=True)
    assert plan is not None and plan.start == pytest.approx(now + 0.05)


def test_an_offered_move_is_checked_and_taken_only_from_where_the_arm_is(cell):
    """The job's plan offered to a planner: refused if it is not a plan, used from the arm only.

    :func:`offered_move` refuses a plan without velocities or accelerations, one that does not
    start at t = 0 and one outside the joint limits; :func:`starts_at` says whether it starts
    within the tolerance of the measured joints (else the planner plans to its end).
    """
    from scara_collab.core.planning import offered_move, starts_at
    arm = cell.leader
    q0 = np.array([0.2, 1.4, 0.1])
    traj = plan_path(arm, q0, [3.3, -0.6, 0.45], mode='line_or_joint')
    taken = offered_move(arm, traj.t, traj.q, traj.qd, traj.qdd)
    assert_allclose(taken.p, traj.p, atol=1e-12)
    assert starts_at(taken, q0, 0.002)
    assert starts_at(taken, q0 + [0.0019, -0.0019, 0.0019], 0.002)
    assert not starts_at(taken, q0 + [0.0, 0.0021, 0.0], 0.002)
    with pytest.raises(ValueError, match='velocities and accelerations'):
        offered_move(arm, traj.t, traj.q, traj.qd, None)
    with pytest.raises(ValueError, match='starts at t = 0'):
        offered_move(arm, traj.t + 0.1, traj.q, traj.qd, traj.qdd)
    outside = traj.q.copy()
    outside[-1, 2] = arm.upper[2] + 0.01
    with pytest.raises(ValueError, match='joint limits'):
        offered_move(arm, traj.t, outside, traj.qd, traj.qdd)
