"""The moves the sorting job asks for: to an item, to a bin, to park, round a mirrored pair.

:class:`JobMoves` turns the job's decisions into commands and returns them: it opens each
move's request (:meth:`scara_collab.core.lanes.LaneProtocol.open`) and books it on the belt
sharing (:mod:`scara_collab.core.sharing`), so the other lane decides around it; it calls the
grippers (:class:`scara_collab.core.lanes.Grips`) and withdraws the booking of a lane that
leaves its move; it times the move that meets an item
(:func:`scara_collab.core.sorting.intercept`, then around the other arm's booked moves), and
sends a mirrored pair round a waypoint when its arms would come within the planners' margin
(:mod:`scara_collab.core.pairing`). No ROS here.
"""
import math
from typing import Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import pairing, sorting, ssm
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.kinematics import fk
from scara_collab.core.lanes import (GripCommand, Lane, LaneProtocol, MoveCommand, Phase,
                                     PlanMemo)
from scara_collab.core.model import CellModel
from scara_collab.core.trajectory import Trajectory


#: s a meeting the arm could not make at speed near a person is put off by, each time
PUT_OFF = 0.5
#: times a meeting is put off before the item is left for the person
PUT_OFFS = 4
#: s between two looks at whether a person has come near a meeting that has not begun
RECHECK = 0.2
#: s ahead a walking person counts as near an arm if their way leads into its reach: a meeting
#: and the carry to the bin take about this long, and a move that has begun cannot be given up
NEAR_AHEAD = 5.0
#: m: an idle arm kept from every item by a person parks if its park is further than this
AWAY = 0.1
#: a move's states (:class:`~scara_collab.core.lanes.MoveTrack`) while its planner holds it
UNSENT = ('asked', 'queued', 'waiting')


class JobMoves:
    """Ask the job's moves and grips, and book them on the belt (see the module docstring).

    :param belt: the belt sharing (:class:`~scara_collab.core.sharing.SharedBelt` or
        :class:`~scara_collab.core.sharing.SoloBelt`).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, protocol: LaneProtocol, belt,
                 plan: PlanMemo, people: Optional[ssm.SsmParams] = None):
        """Nothing asked yet.

        :param people: the protective separation's numbers of a cell with a safety scanner
            (the meeting with an item is then chosen where the arm can work at speed).
        """
        self.cell, self.settings, self.protocol, self.belt, self.plan = (
            cell, settings, protocol, belt, plan)
        self.people = people
        #: the persons the separation monitor sees, as it last said (none without a scanner)
        self.persons: Sequence[ssm.Person] = ()
        #: why the last :meth:`meet` asked nothing: ``'person'`` if only a person was in the way
        self.declined = ''
        self._rechecked: Dict[str, float] = {}  # sim s of each lane's last look (person_in_way)

    def go(self, lane: Lane, phase: Phase, target, start: float, now: float,
           traj: Optional[Trajectory] = None) -> MoveCommand:
        """Return ``lane``'s move to ``target`` from ``start``, opened and booked on the belt."""
        cmd = self.protocol.open(lane, phase, target, start, now, traj)
        self.belt.book(lane)
        return cmd

    def call_grippers(self, lane: Lane, grasp: bool, now: float) -> List[GripCommand]:
        """Return the calls of ``lane``'s grippers to grasp (True) or release; its move is over."""
        self.belt.settle(lane)
        return self.protocol.grips.ask(lane, grasp, now)

    def free(self, lane: Lane) -> None:
        """Make ``lane`` idle: its item, move and grips forgotten, its booking withdrawn."""
        self.belt.settle(lane)
        lane.idle()

    def meet(self, lane: Lane, item: sorting.SeenItem, now: float) -> List[MoveCommand]:
        """Return the move that meets ``item`` (``[]``: the arm cannot, or not yet)."""
        s = self.settings
        # a mirrored pair's move takes one hop more (the replication manager) to both planners
        start = self.protocol.time.decided(now, lane.mirrored)
        arm = self.cell.arm(lane.robot)
        q = self.protocol.q
        aim = pairing.pair_aim(self.cell, item, s.pair_offset) if lane.mirrored else item
        lead = self.protocol.grips.lead
        hit = sorting.intercept(self.cell, arm, q[lane.robot], aim, start, s.pick_z,
                                lambda q0, p: self.plan(lane.robot, q0, p), lead=lead)
        self.declined = ''
        if hit is not None and self.persons and self.people is not None:
            hit = self._at_speed(lane, aim, hit, lead, now)
        if hit is not None:
            hit = self.belt.unhindered(lane, aim, hit, now, q, lead)
        if hit is None:
            return []
        lane.item = item
        if lane.mirrored and not pairing.pair_clear(self.cell, lane.robot, hit.traj,
                                                    s.pair_margin):
            route = pairing.detour(self.cell, self.plan, lane.robot, q[lane.robot],
                                   hit.target, s.carry_z, s.pair_margin)
            if route:  # go round first, then meet the item from there
                cmd = self.go(lane, Phase.VIA, route[0], start, now)
                lane.route = [(Phase.VIA, p) for p in route[1:]]
                return [cmd]
        return [self.go(lane, Phase.TO_ITEM, hit.target, hit.start, now, hit.traj)]

    def _at_speed(self, lane: Lane, item: sorting.SeenItem, hit: sorting.Intercept,
                  lead: float, now: float) -> Optional[sorting.Intercept]:
        """Return ``hit``, or a later meeting the arm can make faster, away from the persons.

        A meeting the separation monitor would slow below ``person_speed`` (checked on the
        planned move and on the carry from there to the item's bin, against the persons now
        and where they are going, :func:`scara_collab.core.ssm.allowed_along`; an item whose
        bin is next to a person is left to the other arm) is put off: the item met
        further down the belt, later, while it stays in reach, up to ``PUT_OFFS`` times; of
        those, the fastest is taken if the monitor lets the arm move at ``person_least_speed``
        there, else none (None: :attr:`declined` says it was left for the person).
        """
        s, arm = self.settings, self.cell.arm(lane.robot)
        near = self._near(arm)
        if not near:
            return hit
        q0 = self.protocol.q[lane.robot]
        best, best_speed = None, -1.0
        for _ in range(PUT_OFFS + 1):
            if hit is None:
                break
            speed = self._cycle_speed(arm, lane.robot, item.cls, hit.traj, hit.start - now,
                                      near)
            if speed >= s.person_speed:
                return hit
            if speed > best_speed:
                best, best_speed = hit, speed
            hit = sorting.intercept(self.cell, arm, q0, item, hit.start + PUT_OFF, s.pick_z,
                                    lambda a, p: self.plan(lane.robot, a, p), lead=lead)
        if best is not None and best_speed >= s.person_least_speed:
            return best
        self.declined = 'person'
        return None

    def person_in_way(self, lane: Lane, now: float) -> bool:
        """Return True if a person now keeps ``lane``'s meeting from being made at speed.

        A meeting asked before the person came near (or before the person was seen walking
        towards it) that has not begun (its planner holds it, :data:`UNSENT`, or it is sent
        and surely not begun, :meth:`~scara_collab.core.move_time.MoveTime.ahead`: a newer
        request supersedes it either way) is weighed again as :meth:`meet` weighs a new one,
        every :data:`RECHECK` s: below ``person_least_speed`` it had better be given up, before
        the arm takes itself next to the person and is held there. A move that has begun runs
        (it can only be slowed or stopped); a mirrored pair runs as one.
        """
        track = lane.moves.get(lane.robot)
        if lane.phase != Phase.TO_ITEM or lane.mirrored or lane.plan is None or track is None:
            return False
        unsent = track.state in UNSENT
        if not unsent and (track.start is None or not self.protocol.time.ahead(track.start, now)):
            return False  # begun, or about to: it runs
        arm = self.cell.arm(lane.robot)
        near = self._near(arm)
        if not near or now < self._rechecked.get(lane.robot, -math.inf) + RECHECK:
            return False
        self._rechecked[lane.robot] = now
        delay = 0.0 if unsent else track.start - now
        speed = self._cycle_speed(arm, lane.robot, lane.item.cls if lane.item else None,
                                  lane.plan, delay, near)
        return speed < self.settings.person_least_speed

    def bin_kept(self, lane: Lane) -> bool:
        """Return True if a person keeps the item ``lane`` just grasped from its bin.

        The carry from here to the bin, starting now, weighed as :meth:`meet` weighs a cycle:
        below ``person_least_speed`` the arm would be held with the item next to the person
        (for as long as they stay), so it had better let the item go on along the belt.
        """
        arm = self.cell.arm(lane.robot)
        near = self._near(arm)
        if not near or lane.item is None:
            return False
        speed = self._carry_speed(arm, lane.robot, lane.item.cls, self.protocol.q[lane.robot],
                                  0.0, near)
        return speed < self.settings.person_least_speed

    def _near(self, arm) -> List[ssm.Person]:
        """Return the persons who could slow ``arm``: within its reach and largest ``S_p``.

        Now, or on their way within :data:`NEAR_AHEAD` s at the velocity they are seen
        walking at (:func:`~scara_collab.core.ssm.persons_ahead` extrapolates the same way): a
        person walking in is weighed before the arm begins a move towards where they are
        going, not once it is under way and can only be stopped next to them.
        """
        if not self.persons or self.people is None:
            return []
        reach = (arm.l1 + arm.l2 + ssm.true_separation_bound(arm, self.people)
                 + self.people.intrusion + self.people.sensor_tolerance)
        base = arm.base[:2, 3]
        return [p for p in self.persons if _closest(base, p.position,
                                                    p.velocity * NEAR_AHEAD) - p.radius < reach]

    def _speed_along(self, arm, traj: Trajectory, delay: float,
                     near: Sequence[ssm.Person]) -> float:
        """Return the factor the monitor would allow ``traj`` starting ``delay`` s from now.

        Each sample weighed against the persons where they will be when the arm gets there.
        A move slowed to ``s`` takes ``1 / s`` as long, and a person walking in has come that
        much closer by then: a slowed move is weighed once more on its slowed times, and the
        lower factor taken (at speed nothing changes).
        """
        samples = np.linspace(0, len(traj.t) - 1, 5)[1:].round().astype(int)
        q, qd, t = traj.q[samples], traj.qd[samples], traj.t[samples]
        speed = ssm.allowed_along(arm, q, qd, near, self.people, ahead=delay + t)
        if 0.0 < speed < 1.0:
            speed = min(speed, ssm.allowed_along(arm, q, qd, near, self.people,
                                                 ahead=delay + t / speed))
        return speed

    def _cycle_speed(self, arm, robot: str, cls: Optional[str], traj: Trajectory,
                     delay: float, near: Sequence[ssm.Person]) -> float:
        """Return the factor the monitor would allow a meeting and the carry to ``cls``'s bin.

        The meeting ``traj`` starting ``delay`` s from now, then the move from where it ends to
        the bin's drop point, as soon as it ends at the meeting's factor (the grasp's time
        aside): an arm that met an item at speed only to be held with it next to a person's
        bin has done no good.
        """
        speed = self._speed_along(arm, traj, delay, near)
        if cls is None or speed <= 0.0:
            return speed
        return min(speed, self._carry_speed(arm, robot, cls, traj.q[-1],
                                            delay + float(traj.t[-1]) / speed, near))

    def _carry_speed(self, arm, robot: str, cls: str, q0, delay: float,
                     near: Sequence[ssm.Person]) -> float:
        """Return the factor the monitor would allow the carry from ``q0`` to ``cls``'s bin.

        Starting ``delay`` s from now; 1 if it cannot be planned (the bin move is planned,
        and refused with the reason, when it is asked).
        """
        drop = sorting.drop_point(self.cell, robot, cls, self.settings.drop_clearance)
        try:
            carry = self.plan(robot, q0, drop)
        except ValueError:
            return 1.0
        return self._speed_along(arm, carry, delay, near)

    def to_bin(self, lane: Lane, now: float) -> List[MoveCommand]:
        """Return the move that carries the item ``lane`` holds to the bin of its class.

        Lifted clear of the items on the belt, it stays at least that high all the way: a line
        from the lift down to the drop point would bring the held item back down to the tops
        of the items it was lifted over, wherever it crosses the belt on its way.
        """
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls,
                                  self.settings.drop_clearance)
        if lane.phase == Phase.LIFT:
            drop[2] = max(drop[2], self.settings.carry_z)
        return self.go_round(lane, Phase.TO_BIN, drop,
                             self.protocol.time.asap(now, lane.mirrored), now)

    def to_park(self, lane: Lane, now: float) -> List[MoveCommand]:
        """Return the move to wait clear of the shared zone, above the first bin.

        Near a person, above whichever of its bins is furthest from them (a park above a bin
        next to the person would be slowed all the way, and the arm held there).
        """
        return self.go_round(lane, Phase.TO_PARK, self._park_point(lane.robot),
                             self.protocol.time.asap(now, lane.mirrored), now)

    def away_from_person(self, lane: Lane, now: float) -> List[MoveCommand]:
        """Return the park of an idle ``lane`` a person keeps from every item, if elsewhere.

        An arm that took an item to the bin next to a person can meet no item from there at
        speed (every way out passes the person): rather than wait there until they leave, it
        parks above its bin furthest from them, from where it can. Nothing if it is there.
        """
        arm = self.cell.arm(lane.robot)
        point = self._park_point(lane.robot)
        tool = fk(arm, self.protocol.q[lane.robot])
        if not self._near(arm) or np.hypot(*(tool[:2] - point[:2])) < AWAY:
            return []
        return self.to_park(lane, now)

    def _park_point(self, robot: str) -> np.ndarray:
        """Return where ``robot`` parks: above its first bin, or the furthest from a person."""
        points = [sorting.drop_point(self.cell, robot, cls, self.settings.drop_clearance)
                  for cls in self.cell.item_classes]
        near = self._near(self.cell.arm(robot))
        if not near:
            return points[0]
        room = [min(np.hypot(*(p[:2] - person.position)) - person.radius for person in near)
                for p in points]
        return points[int(np.argmax(room))]

    def park_unused(self, robots: List[str], now: float) -> List[MoveCommand]:
        """Return the moves of the arms no lane uses to wait above their first bin."""
        out = []
        for robot in robots:
            park = sorting.drop_point(self.cell, robot, self.cell.item_classes[0],
                                      self.settings.drop_clearance)
            out.append(self.protocol.open_once(robot, park, self.protocol.time.decided(now),
                                               'park'))
        return out

    def go_round(self, lane: Lane, phase: Phase, target, start: float,
                 now: float) -> List[MoveCommand]:
        """Return the move like :meth:`go`; a mirrored pair may go round by a waypoint first.

        A pair that would come within the planners' margin goes round, so the follower need
        not yield and both arms start together.
        """
        if lane.mirrored:
            q0 = self.protocol.q[lane.robot]
            margin = self.settings.pair_margin
            try:
                clear = pairing.pair_clear(self.cell, lane.robot,
                                           self.plan(lane.robot, q0, target), margin)
            except ValueError:
                clear = True  # the planner will refuse it with the reason
            route = [] if clear else pairing.detour(self.cell, self.plan, lane.robot, q0,
                                                    target, self.settings.carry_z, margin)
            if route:
                cmd = self.go(lane, Phase.VIA, route[0], start, now)
                lane.route = [(Phase.VIA, p) for p in route[1:]] + [(phase, np.asarray(target))]
                return [cmd]
        return [self.go(lane, phase, target, start, now)]

    def would_sweep(self, lane: Lane, items: Dict[int, sorting.SeenItem], now: float) -> bool:
        """Return True if the item just grasped would touch one of ``items`` on its way.

        Then it is lifted clear first: the move to the bin, planned as the job will offer it
        to the planner (the plan memo keeps it for that request), is checked against every
        other item's predicted position with ``carry_clearance`` to spare
        (:func:`scara_collab.core.sorting.carry_sweeps`; in mirrored mode the follower's
        mirror image too), over every start up to the worst start lateness measured lately
        (a late move meets the items further down the belt). Checking costs about a
        millisecond; lifting costs a move.
        """
        s = self.settings
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, s.drop_clearance)
        try:
            traj = self.plan(lane.robot, self.protocol.q[lane.robot], drop)
        except ValueError:
            return True
        others = [it for it in items.values() if it.id != lane.item.id]
        spare = s.carry_z - s.pick_z - self.cell.item_size  # = carry_clearance
        return bool(others) and sorting.carry_sweeps(
            self.cell, traj.p, self.protocol.time.asap(now, lane.mirrored) + traj.t, others,
            s.pick_z, spare, mirrored=lane.mirrored, late=self.protocol.time.late.worst)


def _closest(point: np.ndarray, start: np.ndarray, way: np.ndarray) -> float:
    """Return the distance from ``point`` to the segment from ``start`` along ``way`` (2D).

    >>> _closest(np.zeros(2), np.array([-3.0, 1.0]), np.array([6.0, 0.0]))
    1.0
    >>> _closest(np.zeros(2), np.array([3.0, 4.0]), np.array([3.0, 0.0]))
    5.0
    """
    w = np.asarray(way, dtype=float)
    length2 = float(w @ w)
    t = 0.0 if length2 <= 0.0 else min(max(float((point - start) @ w) / length2, 0.0), 1.0)
    return float(np.hypot(*(start + t * w - point)))
