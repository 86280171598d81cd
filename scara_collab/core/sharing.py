"""Two lanes over one belt, without ROS: waits broken, the shared zone booked in time.

:class:`SharedBelt` is the layer of the job between the request protocol
(:class:`scara_collab.core.lanes.LaneProtocol`) and the sorting decisions
(:class:`scara_collab.core.job.SortingJob`) that deals with the other arm: a chase timed around
the other arm's booked motion (:meth:`SharedBelt._unhindered`), an arm that waits for the other
unblocked (parks, gives way, backs out or re-aims: :meth:`SharedBelt._unblock`), a mirrored
pair kept apart by a detour (:meth:`SharedBelt._move_safely`). What each arm is committed to
is booked here too: a move as the job planned it when it asked (:meth:`SharedBelt._book_asked`),
then as the planner published it (:meth:`SharedBelt.on_trajectory`, :meth:`SharedBelt._book`),
read back by :meth:`SharedBelt._committed`. The geometry is
:mod:`scara_collab.core.pairing`'s; with one lane nothing here acts.
"""
from typing import Dict, List, Optional

import numpy as np

from scara_collab.core import pairing, planning, sorting
from scara_collab.core.lanes import Lane, LaneProtocol, MoveCommand, MoveTrack, MOVING

#: s: an item with less than this left in an arm's reach is urgent: about two cycles, so of
#: two urgent items the arm can still take the one after the other. An urgent item is chased
#: even when the other arm's booked move will hold the arm up (else the arm may take another
#: first and come back too late, or both arms may defer it until it is missed)
URGENT_SLACK = 8.0


class SharedBelt(LaneProtocol):
    """The job's dealings with the other arm (see the module docstring).

    The subclass provides ``items`` (the items resting on the belt, by id) and the chase
    (:meth:`_chase`).
    """

    items: Dict[int, sorting.SeenItem]

    def __init__(self, *args, **kwargs):
        """Set up the lanes (:class:`LaneProtocol`); no arm parked yet, no move held."""
        super().__init__(*args, **kwargs)
        self._parked_unused = False
        self._held: List[MoveCommand] = []  # the follower's moves, held for the leader's answer
        self._held_since = 0.0

    def _chase(self, lane: Lane, item: sorting.SeenItem, now: float) -> bool:
        """Ask for the move that meets ``item``; return False if the arm cannot."""
        raise NotImplementedError

    # --- in turn: the leader's move first ----------------------------------------------------
    def _in_turn(self, out: List[object], now: float) -> List[object]:
        """Return ``out`` with the follower's moves held while the leader's awaits its planner.

        The follower's planner schedules its move against the leader's trajectories (the
        priority rule). Sent in the same tick, the follower's offer can reach its planner
        before or after the leader's new trajectory, depending on how the processes are
        scheduled: the follower then plans at once or answers "waiting", and the run differs
        (seen with two CPU hogs on two cores). Held until the leader's planner has answered
        (its trajectory goes out before its status), the follower's offer always comes after
        it. A leader's answer that does not come releases them after ``answer_timeout`` (the
        leader's move is then sent again). With one lane nothing is held.
        """
        if len(self.lanes) < 2:
            return out
        lead = self.cell.leader.name
        keep, follower = [], []
        for c in out:
            (follower if isinstance(c, MoveCommand) and c.robot != lead else keep).append(c)
        if follower:
            if not self._held:
                self._held_since = now
            self._held += follower
        out = keep
        leader = next(lane for lane in self.lanes if lane.robot == lead)
        asking = leader.phase in MOVING and any(t.state == 'asked'
                                                for t in leader.moves.values())
        if self._held and (not asking or now - self._held_since >= self.s.answer_timeout):
            out, self._held = out + self._held, []
        return out

    # --- what each arm has booked ------------------------------------------------------------
    def on_trajectory(self, robot: str, request: int, t: np.ndarray, q: np.ndarray) -> None:
        """Take the trajectory a planner published for ``robot``'s move ``request``.

        With two lanes it is the motion the move commits the arm to (its booking, see
        :meth:`_book`); a later start reported by the bridge shifts it.

        :param t: ``(N,)`` absolute sim times, s; :param q: ``(N, 3)`` joint positions.
        """
        track = self._open_track(robot, request)
        if len(self.lanes) < 2 or track is None:
            return
        track.timeline = planning.Timeline(np.asarray(t, dtype=float), np.asarray(q, dtype=float))
        if track.start is not None:  # already timed: the start that counts
            self._book(robot, request, track)

    def _book(self, robot: str, request: int, track: MoveTrack) -> None:
        """Keep the motion a timed move commits ``robot`` to (two lanes: each one's look-ahead).

        It is the trajectory the planner published (:meth:`on_trajectory`), shifted to the
        start the planner's ``planned`` or the bridge's ``accepted`` reports. Only if that
        message has not come (lost, or overtaken by the status) is the move planned here, as
        the planner did, from where the arm is when the move is first timed (it has not
        started yet).
        """
        if len(self.lanes) < 2 or track.start is None:
            return
        if track.timeline is not None:
            track.timeline = track.timeline.shifted(track.start - track.timeline.start)
            return
        lane = next(la for la in self.lanes if la.request == request and robot in la.moves)
        try:
            traj = self.plan(robot, self.q[robot], self._target_of(lane, robot))
        except (ValueError, KeyError):
            return
        track.timeline = planning.Timeline.of(traj, track.start)

    def _committed(self, robot: str, now: float) -> planning.Timeline:
        """Return ``robot``'s motion from ``now`` as far as it is booked (else it holds).

        Booked: a move the planner timed (``planned``, ``accepted``), or one just asked for,
        as the job planned it when it asked (:meth:`_book_asked`): in the ticks before the
        planner's answer the other lane must not decide as if the arm stood still.
        """
        for lane in self.lanes:
            track = lane.moves.get(robot) if lane.phase in MOVING else None
            if (track is not None and track.timeline is not None
                    and track.state in ('asked', 'planned', 'accepted')
                    and track.timeline.end > now):
                return track.timeline
        return planning.Timeline.hold(now, self.q[robot])

    def _book_asked(self, lane: Lane) -> None:
        """Book a move just asked for as the job planned it (:meth:`LaneProtocol._move`).

        It stands until the planner's own trajectory comes (:meth:`on_trajectory`); a move
        the job cannot plan is booked once the planner has timed it (:meth:`_book`).
        """
        if len(self.lanes) > 1 and lane.plan is not None:
            lane.moves[lane.robot].timeline = planning.Timeline.of(lane.plan,
                                                                   lane.request * 1e-9)

    # --- out of the way ------------------------------------------------------------------------
    def _park(self, lane: Lane, now: float) -> None:
        """Wait clear of the shared zone, above the first bin, so the other arm is free."""
        park = sorting.drop_point(self.cell, lane.robot, self.cell.item_classes[0],
                                  self.s.drop_clearance)
        self._move_safely(lane, 'to_park', park, self._soon(lane, now), now)

    def _park_unused(self, now: float) -> None:
        """Arms no lane uses wait above their first bin, off the belt (once)."""
        self._parked_unused = True
        used = {r for lane in self.lanes for r in lane.robots}
        for arm in self.cell.arms:
            if arm.name not in used:
                park = sorting.drop_point(self.cell, arm.name, self.cell.item_classes[0],
                                          self.s.drop_clearance)
                req = self._request([arm.name], now + self.s.decision_lead)
                self._out.append(MoveCommand(arm.name, park, req, False, 'park'))

    def _blocked(self, lane: Lane, now: float) -> bool:
        """Return True if the lane's planner has waited for the other arm ``unblock_after``."""
        return lane.phase in MOVING and any(
            t.state == 'waiting' and now - t.since > self.s.unblock_after
            for t in lane.moves.values())

    def _unblock(self, now: float) -> None:
        """Clear the way for an arm that waits for the other one (collaborative mode).

        An idle arm in the way parks; when both wait for each other, the follower's lane
        gives way (unless it holds an item), as the priority rule has it. When both hold
        items (neither may put its item down), the follower first backs out of the shared zone
        by a waypoint on its own side (:meth:`_retreat`), then goes to its bin. An arm on its
        way to an item that waits for the other arm's work (it will leave when done) re-aims
        at the item as the belt carries it on (:meth:`_reaim`).
        """
        for lane in self.lanes:
            if not self._blocked(lane, now):
                continue
            other = next(o for o in self.lanes if o is not lane)
            if other.phase == 'idle':
                self.log('info', f'{other.robot}: parks to clear the way for {lane.robot}')
                self._park(other, now)
            elif not self._blocked(other, now):
                if lane.phase == 'to_item' and not lane.holding:
                    self._reaim(lane, other, now)
            else:
                # the one not holding an item gives way; if neither holds one, the follower
                free = [o for o in (lane, other) if not o.holding]
                if free:
                    yielder = next((o for o in free if o.robot != self.cell.leader.name),
                                   free[0])
                    self._give_up(yielder, now, 'both arms wait for each other: '
                                  f'{yielder.robot} gives way')
                else:  # both carry items: one backs out of the way, follower first
                    for o in sorted((lane, other), key=lambda o: o.robot ==
                                    self.cell.leader.name):
                        if o.phase != 'via' and self._retreat(o, now):
                            break
            return

    def _reaim(self, lane: Lane, other: Lane, now: float) -> None:
        """Ask again for the item an arm waits to meet, where the belt has carried it by now.

        The planner holds a waiting move until the other arm's next move clears the way (the
        other arm waits at an item or its bin while it grips), then plans the target it has:
        by then the item has moved on. Asking again every ``unblock_after`` keeps the target
        current, so the arm meets the item as soon as the way is clear; the item's deadline
        is the belt's end (the intercept no longer exists: give up).
        """
        seen = self.items.get(lane.item.id)
        if seen is None:  # not seen resting on the belt just now: the move's deadline holds
            return
        if lane.reaims == 0:
            self.log('info', f'{lane.robot}: waits for {other.robot} ({other.phase}); '
                     f're-aims at item {seen.id} while it waits')
        if not self._chase(lane, seen, now):
            return self._give_up(lane, now, f'item {seen.id} got away while {lane.robot} '
                                 f'waited for {other.robot}')
        lane.reaims += 1

    def _retreat(self, lane: Lane, now: float) -> bool:
        """Back an arm holding an item out of the shared zone, then on to its bin.

        The waypoint is :func:`scara_collab.core.pairing.retreat_via` (out from the belt on
        the arm's own side, clear of the other arm where it stands). Return False if there is
        none (then the other arm backs out).
        """
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        q_other = self.q.get(other.name)
        if q_other is None:
            return False
        via = pairing.retreat_via(self.cell, self.plan, lane.robot, self.q[lane.robot],
                                  q_other, self.s.carry_z, self.s.pair_margin)
        if via is None:
            return False
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, self.s.drop_clearance)
        self.log('info', f'{lane.robot}: both arms hold items and wait for each other: '
                 f'{lane.robot} backs out to y={via[1]:.2f} first')
        lane.route = [('to_bin', drop)]
        self._move(lane, 'via', via, self._soon(lane, now), now)
        return True

    def _unhindered(self, lane: Lane, item: sorting.SeenItem, hit: sorting.Intercept,
                    now: float) -> Optional[sorting.Intercept]:
        """Return the chase timed around the other arm's booked move, or None to defer it.

        :func:`scara_collab.core.pairing.unhindered` against what the other arm has booked
        (:meth:`_committed`), with the planners' margin; a wait of up to half the grasp
        reach's belt travel is taken as it is. An item with less than ``URGENT_SLACK`` left in
        reach is never deferred for a wait (in an hour's soak both arms deferred one item until
        it was missed), but it is met where it will be when the way is clear (in another soak
        an arm chased such an item on the un-delayed time, arrived 4.7 cm late at the end of
        its reach and lost it).
        """
        arm = self.cell.arm(lane.robot)
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        if other.name not in self.q:
            return hit
        p = sorting.predict(self.cell, item, now)
        urgent = sorting.time_in_reach(self.cell, arm, p, self.s.pick_z) < URGENT_SLACK
        return pairing.unhindered(
            self.cell, self.plan, lane.robot, self.q[lane.robot], item, hit,
            self._committed(other.name, now), self.s.pick_z, self.s.pair_margin,
            tolerance=0.5 * self.s.grasp_reach / max(self.cell.belt.speed, 1e-9),
            max_delay=self.s.move_timeout, urgent=urgent, lead=self.grasp_lead)

    def _move_safely(self, lane: Lane, phase: str, target, start: float, now: float) -> None:
        """Ask for a move like :meth:`_move`; a mirrored pair may go round by a waypoint.

        A pair that would come within the planners' margin goes round, so the follower need
        not yield and both arms start together.
        """
        if len(lane.robots) > 1:
            q0 = self.q[lane.robot]
            try:
                clear = pairing.pair_clear(self.cell, lane.robot,
                                           self.plan(lane.robot, q0, target), self.s.pair_margin)
            except ValueError:
                clear = True  # the planner will refuse it with the reason
            route = [] if clear else pairing.detour(self.cell, self.plan, lane.robot, q0,
                                                    target, self.s.carry_z, self.s.pair_margin)
            if route:
                lane.route = [('via', p) for p in route[1:]] + [(phase, np.asarray(target))]
                self._move(lane, 'via', route[0], start, now)
                return
        self._move(lane, phase, target, start, now)
