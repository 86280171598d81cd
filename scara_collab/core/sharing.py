"""How the job shares the belt between its lanes, without ROS: one strategy, chosen once.

The job holds one of two objects with the same methods:

- :class:`SoloBelt` (one lane: ``single``, and ``mirrored``, whose one lane moves both arms):
  nothing to book, nothing to hold, nobody to wait for;
- :class:`SharedBelt` (``collaborative``: a lane per arm): the shared zone booked in time.
  What each arm is committed to is the committed-motion model's
  (:class:`scara_collab.core.motion.Heard`: every trajectory the arm was sent, a raw one too,
  and the bridge's word on it; :meth:`SharedBelt.on_trajectory`, :meth:`SharedBelt.on_status`).
  A move of the job's is booked in that model as the job planned it when it asked
  (:meth:`SharedBelt.book`), kept in step with its planner's and the bridge's answers
  (:meth:`SharedBelt.answered`: timed, or not counting while queued or waiting) and withdrawn
  when the lane leaves it (:meth:`SharedBelt.settle`); :meth:`SharedBelt.committed` reads it
  back. From that it times a chase around the other arm's booked motion
  (:meth:`SharedBelt.unhindered`), tells the job how to unblock an arm that waits for the
  other (:meth:`SharedBelt.blocked`: park, re-aim, give way or back out), and holds the
  follower's moves until the leader's planner has answered (:meth:`SharedBelt.in_turn`).

Neither keeps the lanes: the job passes them in; the geometry is
:mod:`scara_collab.core.pairing`'s.
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import pairing, planning, sorting
from scara_collab.core.config import load_config
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.lanes import (Command, Lane, MoveCommand, MoveTrack, MOVING, Phase,
                                     PlanFn)
from scara_collab.core.model import CellModel
from scara_collab.core.motion import Heard

#: s: an item with less than this left in an arm's reach is urgent: about two cycles, so of
#: two urgent items the arm can still take the one after the other. An urgent item is chased
#: even when the other arm's booked move will hold the arm up (else the arm may take another
#: first and come back too late, or both arms may defer it until it is missed)
URGENT_SLACK = 8.0
#: what :meth:`SharedBelt.blocked` may ask of the job
UNBLOCK_ACTIONS = ('park', 'reaim', 'give_way', 'back_out')
#: the states of a move of the job's in which its planner has it in hand (its booking counts)
IN_HAND = ('asked', 'planned', 'accepted')

Joints = Dict[str, np.ndarray]


@dataclass(frozen=True, eq=False)
class Unblock:
    """What the job should do for an arm that waits for the other one.

    ``action`` (one of :data:`UNBLOCK_ACTIONS`) is about ``lane``:

    - ``park``: ``lane`` is idle in the way of ``other``: it parks;
    - ``reaim``: ``lane`` waits to meet its item while ``other`` works: it asks again for the
      item where the belt has carried it;
    - ``give_way``: both wait for each other: ``lane`` gives its move up (``why``);
    - ``back_out``: both wait and both hold items: ``lane`` backs out to ``via`` (world),
      then goes on to its bin.
    """

    action: str
    lane: Lane
    other: Optional[Lane] = None
    via: Optional[np.ndarray] = None
    why: str = ''


class SoloBelt:
    """One lane on the belt: nothing is booked, held or unblocked (see the module docstring).

    The parameters are :class:`SharedBelt`'s, so the job builds either the same way.
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn):
        """Nothing to keep."""

    def book(self, lane: Lane) -> None:
        """Book nothing."""

    def answered(self, robot: str, track: MoveTrack, target: np.ndarray, q: Joints) -> None:
        """Book nothing."""

    def settle(self, lane: Lane) -> None:
        """Book nothing."""

    def on_trajectory(self, robot: str, move_id: str, request: Optional[int], stamp: float,
                      t: np.ndarray, q_traj: np.ndarray, now: float, q: Joints) -> None:
        """Book nothing."""

    def on_status(self, robot: str, state: str, move_id: str, start: Optional[float],
                  now: float, q: Joints) -> None:
        """Book nothing."""

    def on_clock(self, robot: str, lag: float) -> None:
        """Book nothing."""

    def unhindered(self, lane: Lane, item: sorting.SeenItem, hit: sorting.Intercept,
                   now: float, q: Joints, lead: float) -> Optional[sorting.Intercept]:
        """Return ``hit``: no other arm to wait for."""
        return hit

    def blocked(self, lanes: Sequence[Lane], now: float, q: Joints) -> Optional[Unblock]:
        """Return None: no arm waits for another."""
        return None

    def in_turn(self, out: List[Command], lanes: Sequence[Lane], now: float) -> List[Command]:
        """Return ``out``: nothing is held."""
        return out

    def drop_held(self) -> None:
        """Hold nothing."""


class SharedBelt:
    """Two lanes on one belt (see the module docstring).

    :param cell: the cell model.
    :param settings: the job's settings.
    :param plan: ``plan(robot, q_start, target) -> Trajectory`` with the planners' settings
        (raises ``ValueError`` if refused).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn):
        """Nothing booked or held yet."""
        self.cell, self.settings, self.plan = cell, settings, plan
        self._held: List[MoveCommand] = []  # the follower's moves, held for the leader's answer
        self._held_since = 0.0
        dt = 1.0 / float(load_config('simulation')['physics_rate'])
        #: what each arm is committed to, as heard (the bridge's rules) and as the job asked
        self.heard = {a.name: Heard(a.name, dt=dt) for a in cell.arms}

    # --- in turn: the leader's move first ----------------------------------------------------
    def in_turn(self, out: List[Command], lanes: Sequence[Lane], now: float) -> List[Command]:
        """Return ``out`` with the follower's moves held while the leader's awaits its planner.

        The follower's planner schedules its move against the leader's trajectories (the
        priority rule). Sent in the same tick, the follower's offer can reach its planner
        before or after the leader's new trajectory, depending on how the processes are
        scheduled: the follower then plans at once or answers "waiting", and the run differs
        by how the processes were scheduled. Held until the leader's planner has answered
        (its trajectory goes out before its status), the follower's offer always comes after
        it. A leader's answer that does not come releases them after ``answer_timeout`` (the
        leader's move is then sent again).
        """
        lead = self.cell.leader.name
        keep, follower = [], []
        for c in out:
            (follower if isinstance(c, MoveCommand) and c.robot != lead else keep).append(c)
        if follower:
            if not self._held:
                self._held_since = now
            self._held += follower
        out = keep
        leader = next(lane for lane in lanes if lane.robot == lead)
        asking = leader.phase in MOVING and any(t.state == 'asked'
                                                for t in leader.moves.values())
        if self._held and (not asking
                           or now - self._held_since >= self.settings.answer_timeout):
            out, self._held = out + self._held, []
        return out

    def drop_held(self) -> None:
        """Forget the held moves (nothing new is commanded: each lane asks again in time)."""
        self._held = []

    # --- what each arm is committed to ---------------------------------------------------------
    def on_trajectory(self, robot: str, move_id: str, request: Optional[int], stamp: float,
                      t: np.ndarray, q_traj: np.ndarray, now: float, q: Joints) -> None:
        """Take a trajectory ``robot`` was sent, the job's or not: the arm is committed to it.

        :param move_id: its name; :param request: the job's request it answers (None: not
            one, e.g. a raw command or a hold); :param stamp: its start, s (0: now);
        :param t: ``(N,)`` s from its start; :param q_traj: ``(N, 3)`` joint positions.
        :param now: sim s; :param q: the arms' joints.
        """
        self.heard[robot].trajectory(move_id, stamp, t, q_traj, now, q.get(robot), request)

    def on_status(self, robot: str, state: str, move_id: str, start: Optional[float],
                  now: float, q: Joints) -> None:
        """Take the bridge's status of any move of ``robot`` (:meth:`.motion.Heard.status`)."""
        self.heard[robot].status(state, move_id, now, start, q.get(robot))

    def on_clock(self, robot: str, lag: float) -> None:
        """Take ``robot``'s trajectory clock (:meth:`.motion.Heard.on_clock`)."""
        self.heard[robot].on_clock(lag)

    def book(self, lane: Lane) -> None:
        """Book the move ``lane`` just asked for as the job planned it (``lane.plan``).

        It stands until the planner's own trajectory comes (:meth:`on_trajectory`); a move
        the job could not plan is booked once the planner has timed it (:meth:`answered`).
        """
        timeline = (None if lane.plan is None
                    else planning.Timeline.of(lane.plan, lane.request * 1e-9))
        self.heard[lane.robot].book(lane.request, timeline)

    def answered(self, robot: str, track: MoveTrack, target: np.ndarray, q: Joints) -> None:
        """Keep ``robot``'s booking in step with its move's new state (``track``).

        It counts while the planner has the move in hand (:data:`IN_HAND`). Timed (``planned``
        or ``accepted``) before its trajectory was heard, it is shifted to the start reported;
        if the job could not plan it when it asked, it is planned here, as the planner did,
        from where the arm is now (``q``; it has not started yet) to ``target``.
        """
        booked = self.heard[robot].booked
        if booked is None:
            return
        booked.counts = track.state in IN_HAND
        if track.state not in ('planned', 'accepted') or track.start is None or booked.heard:
            return
        if booked.timeline is not None:
            booked.timeline = booked.timeline.shifted(track.start - booked.timeline.start)
            return
        try:
            traj = self.plan(robot, q[robot], target)  # one arm per lane
        except (ValueError, KeyError):
            return
        booked.timeline = planning.Timeline.of(traj, track.start)

    def settle(self, lane: Lane) -> None:
        """Withdraw the bookings of ``lane``'s arms: it has left its move (a grip, idle)."""
        for robot in lane.robots:
            self.heard[robot].booked = None

    def committed(self, robot: str, now: float, q: Joints) -> planning.Timeline:
        """Return ``robot``'s motion from ``now`` as far as it is booked (else it holds at ``q``).

        A move of the job's not heard yet (asked, or timed while its trajectory was lost) is
        booked as the job planned it: in the ticks before the planner's answer the other lane
        must not decide as if the arm stood still. Otherwise the arm is committed to what was
        heard (the moves it runs or waits to run, the job's or not):
        :meth:`scara_collab.core.motion.Heard.committed`.
        """
        return self.heard[robot].committed(now, q[robot])

    # --- out of the way ------------------------------------------------------------------------
    def _blocked(self, lane: Lane, now: float) -> bool:
        """Return True if the lane's planner has waited for the other arm ``unblock_after``."""
        return lane.phase in MOVING and any(
            t.state == 'waiting' and now - t.since > self.settings.unblock_after
            for t in lane.moves.values())

    def blocked(self, lanes: Sequence[Lane], now: float, q: Joints) -> Optional[Unblock]:
        """Return how to clear the way for an arm that waits for the other one, or None.

        An idle arm in the way parks; when both wait for each other, the follower's lane
        gives way (unless it holds an item), as the priority rule has it. When both hold
        items (neither may put its item down), the follower first backs out of the shared zone
        by a waypoint on its own side (:func:`scara_collab.core.pairing.retreat_via`), then
        goes to its bin. An arm on its way to an item that waits for the other arm's work (it
        will leave when done) re-aims at the item as the belt carries it on.
        """
        for lane in lanes:
            if not self._blocked(lane, now):
                continue
            other = next(o for o in lanes if o is not lane)
            if other.phase == Phase.IDLE:
                return Unblock('park', other, other=lane)
            if not self._blocked(other, now):
                if lane.phase == Phase.TO_ITEM and not lane.holding:
                    return Unblock('reaim', lane, other=other)
                return None
            # the one not holding an item gives way; if neither holds one, the follower
            free = [o for o in (lane, other) if not o.holding]
            if free:
                yielder = next((o for o in free if o.robot != self.cell.leader.name), free[0])
                return Unblock('give_way', yielder, why='both arms wait for each other: '
                               f'{yielder.robot} gives way')
            # both carry items: one backs out of the way, follower first
            for o in sorted((lane, other), key=lambda o: o.robot == self.cell.leader.name):
                via = self._retreat_via(o, q) if o.phase != Phase.VIA else None
                if via is not None:
                    return Unblock('back_out', o, via=via)
            return None
        return None

    def _retreat_via(self, lane: Lane, q: Joints) -> Optional[np.ndarray]:
        """Return the waypoint that backs ``lane``'s arm out of the shared zone, or None."""
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        q_other = q.get(other.name)
        if q_other is None:
            return None
        return pairing.retreat_via(self.cell, self.plan, lane.robot, q[lane.robot], q_other,
                                   self.settings.carry_z, self.settings.pair_margin)

    def unhindered(self, lane: Lane, item: sorting.SeenItem, hit: sorting.Intercept,
                   now: float, q: Joints, lead: float) -> Optional[sorting.Intercept]:
        """Return the chase timed around the other arm's booked move, or None to defer it.

        :func:`scara_collab.core.pairing.unhindered` against what the other arm has booked
        (:meth:`committed`), with the planners' margin; a wait of up to half the grasp
        reach's belt travel is taken as it is. An item with less than ``URGENT_SLACK`` left in
        reach is never deferred for a wait (else both arms may defer one item until it is
        missed), but it is met where it will be when the way is clear (else the arm arrives
        late at the end of its reach and loses it).

        :param q: the arms' joints; :param lead: the grasp's latency, s.
        """
        s = self.settings
        arm = self.cell.arm(lane.robot)
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        if other.name not in q:
            return hit
        p = sorting.predict(self.cell, item, now)
        urgent = sorting.time_in_reach(self.cell, arm, p, s.pick_z) < URGENT_SLACK
        return pairing.unhindered(
            self.cell, self.plan, lane.robot, q[lane.robot], item, hit,
            self.committed(other.name, now, q), s.pick_z, s.pair_margin,
            tolerance=0.5 * s.grasp_reach / max(self.cell.belt.speed, 1e-9),
            max_delay=s.move_timeout, urgent=urgent, lead=lead)
