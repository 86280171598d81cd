"""Sorting decisions without ROS.

Where a moving item will be met, where it is dropped, which item an arm takes next.

Items ride the belt along +x at ``belt.speed``. An arm that starts moving at ``t_start`` meets
an item where the item will be when the tool arrives: the fixed point of
``T = t_start + duration(move to p(T))``, ``p(T) = p_seen + v (T - t_seen)``. Since ``p``
moves at 0.2 m/s and a move's duration changes by well under 1 s per metre, the iteration is
a contraction and converges in a few steps.
"""
from dataclasses import dataclass
import math
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.core.kinematics import ik
from scara_collab.core.model import ArmModel, CellModel
from scara_collab.core.trajectory import Trajectory

#: what can happen to an item, in the bridge's ``conveyor/events``: the one list of kinds.
#: ``received`` and ``handed_on`` are a line's (:mod:`scara_collab.core.line`): an item put on
#: this section's belt by the cell upstream, and one carried past its end to the cell
#: downstream (the last cell of a line, and a cell on its own, miss it instead).
ITEM_EVENTS = ('spawned', 'received', 'grasped', 'released', 'slipped', 'sorted', 'wrong_bin',
               'missed', 'handed_on', 'dropped')
#: the kinds a run counts (its summary has one number for each)
COUNTED = ('spawned', 'received', 'sorted', 'missed', 'handed_on', 'wrong_bin', 'dropped')
#: after these the item has left the cell
GONE = ('sorted', 'wrong_bin', 'missed', 'handed_on', 'dropped')


@dataclass(frozen=True)
class SeenItem:
    """An item on the belt as last seen.

    :ivar id: item id; :ivar cls: class; :ivar position: ``(3,)`` centre in world, m;
    :ivar stamp: when it was seen, s (sim time).
    """

    id: int
    cls: str
    position: np.ndarray
    stamp: float


@dataclass(frozen=True)
class Intercept:
    """Where and when a tool meets an item.

    ``target`` (tool tip, world), ``arrive`` (s), the planned ``traj`` and when it must
    ``start`` (s) to arrive then.
    """

    target: np.ndarray
    arrive: float
    traj: Trajectory
    start: float


#: m: an item whose centre is this close to its resting height on the belt lies on the belt
BELT_HEIGHT_TOLERANCE = 0.01


def at_belt_height(cell: CellModel, z: float) -> bool:
    """Return True if an item centre at height ``z`` rests on the belt (not held or falling)."""
    return abs(z - (cell.belt.top_z + cell.item_size / 2.0)) < BELT_HEIGHT_TOLERANCE


def on_belt(cell: CellModel, p) -> bool:
    """Return True if an item centre at ``p`` (world) rests on the belt: its height, its area.

    The height alone is not enough: an item dropped into a bin passes the belt's height while
    it falls (a job that took it for an item on the belt chased it into the bin).

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> on_belt(cell, (1.0, 0.2, 0.25)), on_belt(cell, (3.4, 2.1, 0.25))
    (True, False)
    """
    belt = cell.belt
    x, y, z = (float(v) for v in p)
    return (at_belt_height(cell, z) and abs(y - belt.centre_y) <= belt.width / 2.0
            and belt.x_start <= x <= belt.x_end)


def predict(cell: CellModel, item: SeenItem, t: float) -> np.ndarray:
    """Return the item centre at time ``t`` if it stays on the belt."""
    return item.position + np.array([cell.belt.speed * (t - item.stamp), 0.0, 0.0])


def pick_height(cell: CellModel, clearance: float) -> float:
    """Return the tool-tip height for a grasp: ``clearance`` above an item's top."""
    return cell.belt.top_z + cell.item_size + clearance


def drop_point(cell: CellModel, robot: str, cls: str, clearance: float) -> np.ndarray:
    """Return the tool-tip position above the bin of ``cls`` of ``robot``.

    The held item clears the walls by ``clearance``.
    """
    floor = cell.bins[(robot, cls)]
    wall = float(cell.config['bins']['size'][2])
    return np.array([floor[0], floor[1], floor[2] + wall + cell.item_size + clearance])


def joint_time(arm: ArmModel, q0, q1) -> float:
    """Return a lower bound on a move's duration: the slowest joint's trapezoid, s."""
    d = np.abs(np.asarray(q1, float) - np.asarray(q0, float))
    v, a = arm.max_velocity, arm.max_acceleration
    t = np.where(d > v * v / a, d / v + v / a, 2.0 * np.sqrt(d / a))
    return float(t.max())


def meet_bound(cell: CellModel, arm: ArmModel, q_start, item: SeenItem, t_start: float,
               z: float, iterations: int = 8,
               tol: float = 0.003) -> Optional[Tuple[float, Optional[np.ndarray]]]:
    """Return the earliest time the tool could meet ``item`` by the joint-time bound, no planning.

    From when the item enters the arm's reach, the meeting time is raised to ``t_start`` plus
    the bound (:func:`joint_time`) of the move to where the item is then, until it settles.

    :return: ``(time, joints at the meeting point)`` (joints ``None`` if the item has left
        reach by then), or None if the item never comes into reach from ``t_start`` on.
    """
    speed = max(cell.belt.speed, 1e-9)
    p0 = predict(cell, item, t_start)
    x_in = reach_span(arm, p0[1], z, p0[0], cell.belt.x_end)[0]
    if not np.isfinite(x_in):
        return None
    arrive, q = max(t_start, t_start + (x_in - p0[0]) / speed), None
    for _ in range(iterations):
        p = predict(cell, item, arrive)
        p[2] = z
        sol = ik(arm, p, q_current=q_start)
        if not sol.ok:
            return arrive, None
        q = sol.q
        bound = t_start + joint_time(arm, q_start, sol.q)
        if bound <= arrive + tol / speed:
            break
        arrive = bound
    return arrive, q


def cycle_bound(cell: CellModel, arm: ArmModel, q_start, item: SeenItem, t_start: float,
                z: float, drop_clearance: float) -> float:
    """Return a lower bound of the seconds from ``t_start`` until ``item`` is over its bin.

    The meeting bound (:func:`meet_bound`) plus the joint-time bound of the carry from there
    to the bin of the item's class; ``inf`` if the arm cannot meet it or reach the bin.
    """
    bound = meet_bound(cell, arm, q_start, item, t_start, z)
    if bound is None or bound[1] is None:
        return math.inf
    drop = ik(arm, drop_point(cell, arm.name, item.cls, drop_clearance), q_current=bound[1])
    if not drop.ok:
        return math.inf
    return bound[0] - t_start + joint_time(arm, bound[1], drop.q)


def intercept(cell: CellModel, arm: ArmModel, q_start, item: SeenItem, t_start: float,
              z: float, plan: Callable[[np.ndarray, np.ndarray], Trajectory],
              iterations: int = 8, tol: float = 0.003, lead: float = 0.0) -> Optional[Intercept]:
    """Plan the move from ``q_start`` (at rest, free from ``t_start``) that meets ``item``.

    The meeting time ``T`` is the earliest at which the item is in reach and the tool can be
    there: starting from when the item enters the arm's reach, ``T`` is raised to
    ``t_start + duration(move to p(T))`` until it settles (within ``tol`` of belt travel).
    If the tool would be early (the item is still upstream), the move starts later.

    :param z: tool-tip height at the meeting point (see :func:`pick_height`).
    :param plan: ``plan(q_start, target) -> Trajectory`` (raises ``ValueError`` if refused).
    :param lead: s from the tool's arrival to the grasp taking hold (the gripper call's
        measured latency): the tool waits where the item will be then, not where it is on
        arrival (0 in lockstep, where the call is answered within the tick).
    :return: the :class:`Intercept`, or None if the item leaves the arm's reach first.
    """
    speed = max(cell.belt.speed, 1e-9)
    bound = meet_bound(cell, arm, q_start, item, t_start, z, iterations, tol)
    if bound is None:
        return None
    arrive = bound[0]
    for _ in range(iterations):  # then real plans (usually one or two) until it settles
        p = predict(cell, item, arrive + lead)
        p[2] = z
        try:
            traj = plan(q_start, p)
        except ValueError:
            return None  # out of reach by then
        earliest = t_start + traj.duration
        if earliest <= arrive + tol / speed:  # converged (the item moves < tol meanwhile)
            start = max(t_start, arrive - traj.duration)
            return Intercept(p, start + traj.duration, traj, start)
        arrive = earliest
    return None


def reach_span(arm: ArmModel, y: float, z: float, x_from: float, x_to: float,
               step: float = 0.02) -> Tuple[float, float]:
    """Return where the arm's reach begins and ends along x (lateral ``y``, height ``z``).

    The smallest and the largest x on ``[x_from, x_to]``, sampled every ``step``, that the arm
    reaches; ``(inf, -inf)`` if no sample is in reach.
    """
    xs = np.arange(x_from, x_to + step, step)
    ok = ik(arm, np.stack([xs, np.full_like(xs, y), np.full_like(xs, z)], axis=1)).ok
    if not np.any(ok):
        return float('inf'), float('-inf')
    return float(xs[ok].min()), float(xs[ok].max())


def time_in_reach(cell: CellModel, arm: ArmModel, p: np.ndarray, z: float) -> float:
    """Seconds the belt takes to carry a point at ``p`` (world) out of ``arm``'s reach.

    At tool height ``z``; 0 or less once it is past the arm (or never in its reach).
    """
    exit_x = reach_span(arm, p[1], z, p[0], cell.belt.x_end)[1]
    return max(exit_x - p[0], -1.0) / max(cell.belt.speed, 1e-9)


def order_candidates(cell: CellModel, arm: ArmModel, items: Iterable[SeenItem], now: float,
                     z: float, own_side: Optional[bool], steal: bool,
                     other_cycle: Optional[float] = None, groups: bool = False) -> List:
    """Return the items an arm may take next, most urgent first (closest to leaving reach).

    Items on the arm's own half come first; with ``steal``, the other half's follow. An item on
    the other half comes with the arm's own, by urgency, when the other arm would not get to it
    in time: when ``other_cycle`` (s per item) times one more than the free items on its half
    that leave before it (the other arm is busy with one now) exceeds the time it has left. A
    burst of items on one half is then shared before one gets away.

    :param own_side: ``True`` to keep items on the arm's half of the belt, ``None`` for all.
    :param steal: also offer items on the other half (the other arm is busy).
    :param other_cycle: the other arm's time per item, s; ``None``: never take an item of the
        other half before the arm's own.
    :param groups: return ``(group, item)`` pairs: group 0 for the arm's own items (and the
        other half's it takes with them), 1 for the other half's it takes only after them.
    """
    side = np.sign(arm.base_position[1] - cell.belt.centre_y)
    out = []
    for it in items:
        p = predict(cell, it, now)
        mine = np.sign(p[1] - cell.belt.centre_y) in (side, 0.0)
        if own_side is not None and not mine and not steal:
            continue
        slack = time_in_reach(cell, arm, p, z)
        if slack <= 0.0:
            continue  # already past this arm
        out.append([0 if mine or own_side is None else 1, slack, it, p])
    others = [a for a in cell.arms if a.name != arm.name]
    if other_cycle is not None and own_side is not None and others:
        # the other arm's time left for each item of its half (its own reach), in its order
        theirs = sorted((time_in_reach(cell, others[0], e[3], z), k)
                        for k, e in enumerate(out) if e[0] == 1)
        for ahead, (left, k) in enumerate(theirs):
            if (1 + ahead) * other_cycle > left:
                out[k][0] = 0  # the other arm, busy now, would not get to it in time
    out.sort(key=lambda e: (e[0], e[1]))
    return [(e[0], e[2]) if groups else e[2] for e in out]


def mirror_partner(cell: CellModel, item: SeenItem, others: Sequence[SeenItem],
                   tol: float = 0.03) -> Optional[SeenItem]:
    """Return the item spawned as ``item``'s mirror image (same x and class, y mirrored)."""
    want = item.position * np.array([1.0, -1.0, 1.0]) + [0.0, 2 * cell.belt.centre_y, 0.0]
    best: Dict[float, SeenItem] = {}
    for o in others:
        if o.id == item.id or o.cls != item.cls:
            continue
        d = float(np.linalg.norm(predict(cell, o, item.stamp) - want))
        if d < tol:
            best[d] = o
    return best[min(best)] if best else None


def rank_by_cycle(cell: CellModel, arm: ArmModel, q_start, order: Sequence[Tuple[int, SeenItem]],
                  t_start: float, z: float, drop_clearance: float, urgent_slack: float,
                  savable: int) -> List[Tuple[int, SeenItem]]:
    """Reorder ``order`` (most urgent first, every item in reach): cheap cycles first.

    ``order`` is :func:`order_candidates` with its groups (0: the arm's own items and the
    other half's it must take with them, 1: the other half's it takes only after them);
    groups keep their order. Within them each candidate's cost is the bound of the cycle it
    makes (:func:`cycle_bound`: meet it, carry it to its bin): a red item is met upstream near
    the red bins, a blue one left to ride down to the blue bins. Up to ``savable`` urgent
    items (less than ``urgent_slack`` seconds left in reach) stay in front, most urgent
    first, so an item the arm can still save is not left; more than that means the feed is
    faster than the arm, and every candidate then goes by its cost (the items it cannot save
    anyway are left, not the ones that make its cycles short).
    """
    ranked = []
    for k, (group, item) in enumerate(order):
        p = predict(cell, item, t_start)
        urgent = time_in_reach(cell, arm, p, z) < urgent_slack
        cost = cycle_bound(cell, arm, q_start, item, t_start, z, drop_clearance)
        ranked.append([urgent, group, cost, k, (group, item)])
    if sum(e[0] for e in ranked) > savable:
        for e in ranked:
            e[0] = False  # more urgent items than the arm can save: cost alone
    ranked.sort(key=lambda e: (not e[0], e[3] if e[0] else 0, e[1], e[2], e[3]))
    return [e[4] for e in ranked]


def carry_sweeps(cell: CellModel, path: np.ndarray, times: np.ndarray,
                 items: Iterable[SeenItem], pick_z: float, spare: float,
                 mirrored: bool = False, late: float = 0.0) -> bool:
    """Return True if an item held under the tool along ``path`` would touch one on the belt.

    A held item hangs with its bottom ``pick_z - belt top`` below the tool (it was grasped
    there). Where the tool is low enough for the held item's bottom to come within ``spare``
    of the tops of the items on the belt, their predicted positions at ``times`` are checked
    for overlap (with ``spare``); ``mirrored`` also checks the path's mirror image (a mirrored
    follower's copy).

    :param path: ``(N, 3)`` tool positions (world); :param times: ``(N,)`` when, s (sim).
    :param items: the other items resting on the belt.
    :param late: s the move may start after ``times`` say: every start in between is checked
        (the belt carries an item ``belt.speed * late`` further meanwhile).
    """
    size = cell.item_size
    low = path[:, 2] - pick_z < size + spare  # the held bottom below the item tops
    if not np.any(low):
        return False
    t, xy = np.asarray(times)[low], path[low, :2]
    paths = [xy] + ([xy * [1.0, -1.0] + [0.0, 2 * cell.belt.centre_y]] if mirrored else [])
    reach = size + spare
    carried = cell.belt.speed * max(float(late), 0.0)  # how much further a late start finds it
    back, ahead = min(carried, 0.0) - reach, max(carried, 0.0) + reach
    for it in items:
        x = it.position[0] + cell.belt.speed * (t - it.stamp)
        for p in paths:
            if np.any((p[:, 0] > x + back) & (p[:, 0] < x + ahead)
                      & (np.abs(p[:, 1] - it.position[1]) < reach)):
                return True
    return False
