"""The geometry of two arms over one belt (pure functions): pairs kept apart, retreats, waits."""
import numpy as np
import pytest

from scara_collab.core import collision, pairing, planning, sorting
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.planning import plan_path

HOME = np.array([0.0, 1.5708, 0.0])
MARGIN = 0.13
CARRY_Z = 0.47


@pytest.fixture
def plan(cell):
    """Return the planners' line-or-joint planning of a move (raises ValueError if refused)."""
    return lambda robot, q0, target: plan_path(cell.arm(robot), q0, target, mode='line_or_joint')


def item(cell, x, y, item_id=1):
    """Return an item resting on the belt at ``(x, y)``, seen at t = 0."""
    return sorting.SeenItem(item_id, cell.item_classes[0],
                            np.array([x, y, cell.belt.top_z + cell.item_size / 2]), 0.0)


def test_a_pair_meets_items_off_the_centre_line(cell):
    """An item near the centre line is met ``offset`` out on the leader's side; others as seen."""
    far = item(cell, 1.2, -0.3)
    assert pairing.pair_aim(cell, far, 0.13) is far
    near = item(cell, 1.2, 0.05)
    aim = pairing.pair_aim(cell, near, 0.13)
    side = np.sign(cell.leader.base_position[1] - cell.belt.centre_y)
    assert aim.position[1] == pytest.approx(cell.belt.centre_y + side * 0.13)
    assert (aim.id, aim.cls, aim.stamp) == (near.id, near.cls, near.stamp)
    np.testing.assert_array_equal(aim.position[[0, 2]], near.position[[0, 2]])


def test_a_pair_is_clear_when_the_move_and_its_mirror_image_keep_the_margin(cell, plan):
    """Out on the arm's side the pair keeps apart; at the centre line the images meet."""
    lead = cell.leader.name
    bin_point = sorting.drop_point(cell, lead, cell.item_classes[0], 0.1)
    assert pairing.pair_clear(cell, lead, plan(lead, HOME, bin_point), MARGIN)
    assert not pairing.pair_clear(cell, lead, plan(lead, HOME, [1.2, 0.0, 0.34]), MARGIN)


def test_a_detour_goes_round_by_a_waypoint_whose_legs_keep_the_margin(cell, plan):
    """From the first bin to a far item beside the centre line: out from the belt first."""
    lead = cell.leader.name
    q0 = ik(cell.leader, np.array([0.6, -2.1, 0.4])).q
    target = np.array([3.5, -0.2, 0.34])
    assert not pairing.pair_clear(cell, lead, plan(lead, q0, target), MARGIN)
    route = pairing.detour(cell, plan, lead, q0, target, CARRY_Z, MARGIN)
    assert len(route) == 1
    via = route[0]
    side = np.sign(cell.leader.base_position[1] - cell.belt.centre_y)
    assert side * (via[1] - cell.belt.centre_y) >= pairing.VIA_OFFSETS[0] - 1e-9
    assert via[2] >= CARRY_Z
    leg1 = plan(lead, q0, via)
    assert pairing.pair_clear(cell, lead, leg1, MARGIN)
    assert pairing.pair_clear(cell, lead, plan(lead, leg1.q[-1], target), MARGIN)
    # a target on the centre line itself has no detour: the images meet there
    assert pairing.detour(cell, plan, lead, q0, [1.2, 0.0, 0.34], CARRY_Z, MARGIN) == []


def test_a_retreat_backs_out_on_the_arms_own_side_clear_of_the_other_arm(cell, plan):
    """Straight out from the belt, further out than the tool is, the leg clear of the other."""
    lead, foll = cell.leader, cell.follower
    q_lead = ik(lead, [1.34, -0.26, 0.34]).unwrap()
    q_foll = ik(foll, [0.83, 0.05, 0.34]).unwrap()
    via = pairing.retreat_via(cell, plan, foll.name, q_foll, q_lead, CARRY_Z, MARGIN)
    tool = fk(foll, q_foll)
    assert via[0] == pytest.approx(tool[0]) and via[1] > tool[1] + 0.05 and via[2] >= CARRY_Z
    leg = plan(foll.name, q_foll, via)
    assert np.min(collision.arm_distance(foll, leg.q, lead, q_lead)) >= MARGIN
    # out there already: the next retreat goes further out, or there is none
    q_out = ik(foll, via).unwrap()
    further = pairing.retreat_via(cell, plan, foll.name, q_out, q_lead, CARRY_Z, MARGIN)
    assert further is None or further[1] > via[1] + 0.05


def test_a_chase_waits_for_the_other_arms_booked_motion_only_when_it_must(cell, plan):
    """Clear of the other arm: unchanged; in its way: later, deferred, or as is if urgent."""
    lead, foll = cell.leader, cell.follower
    it = item(cell, 2.6, 0.1)
    z = sorting.pick_height(cell, 0.04)
    hit = sorting.intercept(cell, lead, HOME, it, 0.1, z, lambda q, p: plan(lead.name, q, p))
    tolerance = 0.5 * 0.04 / cell.belt.speed

    def timed(booked, urgent):
        return pairing.unhindered(cell, plan, lead.name, HOME, it, hit, booked, z, MARGIN,
                                  tolerance, max_delay=3.0, urgent=urgent)

    away = planning.Timeline.hold(0.0, mirror_joints(HOME))
    assert timed(away, urgent=False) is hit
    stay = ik(foll, hit.target + [0.0, 0.12, 0.0]).q  # the other tool on the meeting point
    assert timed(planning.Timeline.hold(0.0, stay), urgent=False) is None  # never clear
    assert timed(planning.Timeline.hold(0.0, stay), urgent=True) is hit  # goes and waits
    leaves = ik(foll, np.array([3.3, 1.6, z])).q
    motion = planning.Timeline(np.array([0.0, 2.0, 2.5]), np.array([stay, stay, leaves]))
    later = timed(motion, urgent=True)
    assert later is not None and later.start > hit.start + tolerance
    assert later.target[0] > hit.target[0]  # met where the belt has carried the item by then
