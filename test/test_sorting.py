"""Sorting decisions: intercepts meet the moving item, drops land over the right bin."""
import numpy as np
from numpy.testing import assert_allclose

from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path
from scara_collab.core.sorting import (
    drop_point, intercept, joint_time, mirror_partner, order_candidates, pick_height, predict,
    SeenItem)

CELL = load_cell()
LEFT = CELL.leader


def plan(q0, target):
    """Plan the left arm's move from ``q0`` to ``target`` as the planners do."""
    return plan_path(LEFT, q0, target, mode='line_or_joint')


def home_q():
    """Return the left arm's joints above its first bin."""
    return ik(LEFT, drop_point(CELL, LEFT.name, CELL.item_classes[0], 0.1)).unwrap()


def test_intercept_meets_the_item_where_it_will_be():
    """The intercept meets the item where the belt will have carried it, at pick height."""
    z = pick_height(CELL, 0.04)
    item = SeenItem(7, 'red', np.array([1.2, -0.2, 0.25]), stamp=10.0)
    hit = intercept(CELL, LEFT, home_q(), item, t_start=10.5, z=z, plan=plan)
    assert hit is not None
    where = predict(CELL, item, hit.arrive)
    assert_allclose(hit.target[:2], where[:2], atol=0.003)  # within 3 mm of the item
    assert hit.target[2] == z == CELL.belt.top_z + CELL.item_size + 0.04
    assert_allclose(fk(LEFT, hit.traj.q[-1]), hit.target, atol=1e-6)
    assert hit.start >= 10.5 and hit.arrive == hit.start + hit.traj.duration


def test_items_out_of_reach_are_not_intercepted_and_upstream_ones_are_met_later():
    """Items past reach are not intercepted; upstream ones are met once they come into reach."""
    z = pick_height(CELL, 0.04)
    gone = SeenItem(1, 'red', np.array([4.4, 0.3, 0.25]), stamp=0.0)
    assert intercept(CELL, LEFT, home_q(), gone, 0.0, z, plan) is None
    early = SeenItem(2, 'red', np.array([-0.4, 0.0, 0.25]), stamp=0.0)
    hit = intercept(CELL, LEFT, home_q(), early, 0.0, z, plan)
    assert hit is not None and hit.target[0] > 0.3  # met once it has come into reach
    assert hit.start > 0.0, 'the arm waits for the item instead of arriving early'
    assert_allclose(predict(CELL, early, hit.arrive)[:2], hit.target[:2], atol=1e-9)


def test_drop_points_are_over_the_bins_above_the_walls():
    """Drop points are over the bins' centres, above the walls, and reachable."""
    for (robot, cls), floor in CELL.bins.items():
        p = drop_point(CELL, robot, cls, 0.1)
        assert_allclose(p[:2], floor[:2])
        wall = CELL.config['bins']['size'][2]
        assert p[2] - CELL.item_size >= floor[2] + wall + 0.1 - 1e-12
        assert ik(CELL.arm(robot), p).ok


def test_urgent_items_first_and_own_half_preferred():
    """Candidates come most urgent first, the arm's own half before the other's."""
    z = pick_height(CELL, 0.04)
    a = SeenItem(1, 'red', np.array([3.0, -0.2, 0.25]), 0.0)   # downstream, left half
    b = SeenItem(2, 'red', np.array([1.0, -0.2, 0.25]), 0.0)   # upstream, left half
    c = SeenItem(3, 'blue', np.array([2.5, 0.2, 0.25]), 0.0)   # right half
    assert [i.id for i in order_candidates(CELL, LEFT, [b, a, c], 0.0, z, True, False)] == [1, 2]
    with_steal = order_candidates(CELL, LEFT, [b, a, c], 0.0, z, True, True)
    assert [i.id for i in with_steal] == [1, 2, 3]  # own half first, then the other's
    assert [i.id for i in order_candidates(CELL, LEFT, [b, c, a], 0.0, z, None, False)][0] == 3


def test_an_item_the_busy_other_arm_would_miss_comes_before_the_arms_own():
    """A burst on the right half: the left arm takes the one the right arm cannot reach in time.

    Seen in the hour-long soak (t = 2272-2297 s): five items on the right half, the right arm
    busy at 3.5 s an item, the left arm took its own newer items and one right-half item left
    the belt unpicked.
    """
    z = pick_height(CELL, 0.04)
    own = SeenItem(1, 'red', np.array([1.0, -0.2, 0.25]), 0.0)  # upstream, left half
    burst = [SeenItem(10 + k, 'blue', np.array([2.3 - 0.35 * k, 0.2, 0.25]), 0.0)
             for k in range(5)]  # right half, 6.75 s to 13.75 s left in the right arm's reach
    items = [own] + burst
    plain = order_candidates(CELL, LEFT, items, 0.0, z, True, True)
    assert plain[0].id == 1  # own half first, as before
    shared = order_candidates(CELL, LEFT, items, 0.0, z, True, True, other_cycle=3.6)
    # at 3.6 s an item the right arm gets to items 10 and 11 in time, not to 12, 13, 14
    assert [i.id for i in shared] == [12, 13, 14, 1, 10, 11]
    # nothing to share when the other arm keeps up
    calm = order_candidates(CELL, LEFT, [own, burst[0]], 0.0, z, True, True, other_cycle=3.6)
    assert calm[0].id == 1


def test_joint_time_is_a_lower_bound_of_planned_moves():
    """The joint-space time bound never exceeds a planned move's duration."""
    q0 = home_q()
    target = np.array([2.5, -0.2, 0.34])
    traj = plan(q0, target)
    assert joint_time(LEFT, q0, traj.q[-1]) <= traj.duration + 1e-9


def test_mirror_partner():
    """An item's mirror partner is the same class at the mirrored y, or None."""
    item = SeenItem(1, 'red', np.array([1.0, -0.2, 0.25]), 5.0)
    twin = SeenItem(2, 'red', np.array([1.0, 0.2, 0.25]), 5.0)
    other = SeenItem(3, 'blue', np.array([1.0, 0.2, 0.25]), 5.0)
    assert mirror_partner(CELL, item, [item, other, twin]).id == 2
    assert mirror_partner(CELL, item, [item, other]) is None


def test_candidate_groups_say_which_items_come_with_the_arms_own():
    """With ``groups``, each candidate says whether it comes with the arm's own items (0)."""
    z = pick_height(CELL, 0.04)
    own = SeenItem(1, 'red', np.array([1.0, -0.2, 0.25]), 0.0)
    other = SeenItem(2, 'red', np.array([2.5, 0.2, 0.25]), 0.0)
    plain = order_candidates(CELL, LEFT, [own, other], 0.0, z, True, True)
    grouped = order_candidates(CELL, LEFT, [own, other], 0.0, z, True, True, groups=True)
    assert [(g, it.id) for g, it in grouped] == [(0, 1), (1, 2)]
    assert [it for _, it in grouped] == plain


def test_an_item_falling_into_a_bin_is_not_on_the_belt(cell):
    """At the belt's height but over a bin (falling into it) an item is not on the belt.

    The job once saw a just-sorted item pass the belt's height in its bin, took it for an item
    on the belt and chased it there (a give-up in the collaborative job's test, 1 run in 10).
    """
    from scara_collab.core.sorting import drop_point, on_belt
    z = cell.belt.top_z + cell.item_size / 2
    for robot, cls in cell.bins:
        x, y, _ = drop_point(cell, robot, cls, 0.1)
        assert not on_belt(cell, (x, y, z))
    belt = cell.belt
    assert on_belt(cell, (belt.x_start, belt.centre_y + belt.width / 2, z))
    assert not on_belt(cell, (belt.x_end + 0.01, belt.centre_y, z))
    assert not on_belt(cell, (2.0, belt.centre_y, z + 0.02))  # held above it
