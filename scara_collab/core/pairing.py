"""Two arms over one belt, without ROS: keeping a mirrored pair apart, sharing the zone in time.

The job's geometric decisions about the other arm, as pure functions of the cell, a planning
function and the arms' joints:

- a mirrored pair (the follower moves to the mirror image of the leader's target) must keep
  the planners' margin along the whole move (:func:`pair_clear`), else it goes round by a
  waypoint out from the belt (:func:`detour`), and meets items near the centre line a little
  out on its side (:func:`pair_aim`);
- an arm holding an item that blocks the other backs out of the shared zone first
  (:func:`retreat_via`);
- a chase is timed around the other arm's booked motion (:func:`unhindered`).

``plan(robot, q_start, target) -> Trajectory`` is the planners' own planning (raises
``ValueError`` if refused), so these decisions use the moves the planners will make.
"""
from typing import Callable, List, Optional

import numpy as np

from scara_collab.core import collision, planning, sorting
from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.model import CellModel
from scara_collab.core.trajectory import Trajectory

#: m: waypoints a pair may take to stay apart: this far out from the belt centre line
VIA_OFFSETS = (0.6, 0.9, 1.2)

PlanFn = Callable[[str, np.ndarray, np.ndarray], Trajectory]


def _other(cell: CellModel, robot: str):
    return next(a for a in cell.arms if a.name != robot)


def _side(cell: CellModel, robot: str) -> float:
    """Return +1 or -1: the side of the belt centre line ``robot`` stands on."""
    return float(np.sign(cell.arm(robot).base_position[1] - cell.belt.centre_y))


def pair_clear(cell: CellModel, robot: str, traj: Trajectory, margin: float) -> bool:
    """Return True if ``traj`` of ``robot`` and its mirror image keep ``margin`` all along.

    The mirror image is the follower's copy of the move in mirrored mode.
    """
    me, other = cell.arm(robot), _other(cell, robot)
    d, _ = collision.trajectory_min_distance(me, traj.t, traj.q, other, traj.t,
                                             mirror_joints(traj.q))
    return d >= margin


def detour(cell: CellModel, plan: PlanFn, robot: str, q0: np.ndarray, target, carry_z: float,
           margin: float) -> List[np.ndarray]:
    """Return waypoints (world) whose legs and their mirror images keep ``margin``.

    Candidates lie out from the belt centre line on the arm's side, at ``VIA_OFFSETS``,
    above the start, the target or half way, at ``carry_z`` at least; the first that works
    wins, ``[]`` if none does.
    """
    start = fk(cell.arm(robot), q0)
    target = np.asarray(target, dtype=float)
    side = _side(cell, robot)
    z = max(start[2], target[2], carry_z)
    for off in VIA_OFFSETS:
        for x in (start[0], 0.5 * (start[0] + target[0]), target[0]):
            via = np.array([x, cell.belt.centre_y + side * off, z])
            try:
                leg1 = plan(robot, q0, via)
                leg2 = plan(robot, leg1.q[-1], target)
            except ValueError:
                continue
            if pair_clear(cell, robot, leg1, margin) and pair_clear(cell, robot, leg2, margin):
                return [via]
    return []


def retreat_via(cell: CellModel, plan: PlanFn, robot: str, q0: np.ndarray,
                q_other: np.ndarray, carry_z: float, margin: float) -> Optional[np.ndarray]:
    """Return a waypoint that backs ``robot`` out of the shared zone, away from the other arm.

    Straight out from the belt on the arm's own side (``VIA_OFFSETS`` from the centre line,
    at ``carry_z`` at least) and further out than the tool is now, so a retreat that did not
    clear the way is followed by one further out; the first whose leg keeps ``margin`` from
    the other arm standing at ``q_other``. None if none does.
    """
    arm, other = cell.arm(robot), _other(cell, robot)
    start = fk(arm, q0)
    side = _side(cell, robot)
    for off in VIA_OFFSETS:
        via = np.array([start[0], cell.belt.centre_y + side * off, max(start[2], carry_z)])
        if side * (via[1] - start[1]) < 0.05:
            continue  # out there already (an earlier retreat did not clear the way)
        try:
            leg = plan(robot, q0, via)
        except ValueError:
            continue
        if np.min(collision.arm_distance(arm, leg.q, other, q_other)) >= margin:
            return via
    return None


def pair_aim(cell: CellModel, item: sorting.SeenItem, offset: float) -> sorting.SeenItem:
    """Return where a mirrored pair's leader meets ``item``: at least ``offset`` from the centre.

    Within grasp reach of the item, so the two mirrored tools keep the planners' margin and
    the follower never has to yield: both start together.
    """
    centre = cell.belt.centre_y
    if abs(item.position[1] - centre) >= offset:
        return item
    aim = item.position.copy()
    aim[1] = centre + np.sign(cell.leader.base_position[1] - centre) * offset
    return sorting.SeenItem(item.id, item.cls, aim, item.stamp)


def unhindered(cell: CellModel, plan: PlanFn, robot: str, q0: np.ndarray,
               item: sorting.SeenItem, hit: sorting.Intercept, booked: planning.Timeline,
               z: float, margin: float, tolerance: float, max_delay: float,
               urgent: bool, lead: float = 0.0) -> Optional[sorting.Intercept]:
    """Return the chase ``hit`` timed around the other arm's booked motion, or None.

    The chase is scheduled against ``booked`` (:func:`scara_collab.core.planning.schedule`
    with the planners' ``margin``), first booked, first served: the leader too respects a
    move the follower has already booked, though its planner would make the follower yield (it
    does when a conflict comes anyway: the priority rule stays the planners' safety). A wait
    of up to ``tolerance`` is taken as it is; a longer one moves the meeting later, from
    where the arm waits, so the tool arrives where the item will be then. A chase that is not
    ``urgent`` is deferred (None: the arm takes another item) when even that is held up or the
    item would get away meanwhile; an urgent one is never deferred for a long wait (the arm
    goes and waits if it must, ``hit`` unchanged), only None when the later meeting is out of
    the arm's reach (the other arm may still save the item).

    :param item: the item as the chase aims at it; :param z: the tool height at the meeting.
    :param max_delay: the longest wait that counts as a delay, s (longer: held up).
    :param lead: the grasp's latency (:func:`scara_collab.core.sorting.intercept`).
    """
    arm, other = cell.arm(robot), _other(cell, robot)
    for _ in range(2):
        timed = planning.schedule(arm, hit.traj, hit.start, other, booked, margin,
                                  leader=False, max_delay=max_delay)
        if timed is None:
            return hit if urgent else None  # urgent: wait, re-aimed as the belt moves
        if timed.delay <= tolerance:
            return hit
        hit = sorting.intercept(cell, arm, q0, item, hit.start + timed.delay, z,
                                lambda q, p: plan(robot, q, p), lead=lead)
        if hit is None:
            return None
    return hit if urgent else None
