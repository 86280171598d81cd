"""The sorting job as a state machine, without ROS: observations in, commands out.

:class:`SortingJob` decides everything the automation manager does; the node only turns
messages into the ``on_*`` observations, calls :meth:`SortingJob.tick` on a timer and turns
the returned :class:`MoveCommand` / :class:`GripCommand` into messages and service calls.

A *lane* is one arm's work (``single``: the leader; ``collaborative``: one lane per arm;
``mirrored``: one lane that moves both arms, the follower to the mirror image). Its phases:

=============  =================================================  ===========================
phase          leaves when                                        deadline (then)
=============  =================================================  ===========================
``idle``       an item can be met: a pick move is asked           none
``to_item``    every arm's move has arrived (bridge ``finished``  no planner answer:
               or the end time passed with the tool at the        ``answer_timeout``, re-sent
               target): grasp if the item is under the tool,      ``answer_retries`` times;
               else chase it or give up                           not planned by
                                                                  ``move_timeout``; not
                                                                  arrived ``arrive_timeout``
                                                                  after its end (give up,
                                                                  park)
``grasping``   every gripper answered (or the bridge's            ``grip_timeout``, asked
               ``grasped`` event confirmed it)                    again ``grip_retries`` times
                                                                  (give up)
``lift``       as ``to_item``; only when ``carry_height`` lifts   as ``to_item``
               the item above those on the belt
``to_bin``     as ``to_item``                                     as ``to_item`` with
                                                                  ``carry_timeout``; a given
                                                                  up bin move is asked again
``releasing``  every gripper answered (or ``released`` seen)      as ``grasping``
``to_park``    as ``to_item``                                     as ``to_item`` (then idle)
=============  =================================================  ===========================

Every observation names what it is about (a move by its request, a grip by its token), so a
late, duplicated or unknown one is ignored, and every waiting phase has a deadline, so a lost
one costs a retry, never the run. The servers are idempotent (a planner re-publishes the status
of a request it already has; a grasp while holding and a release while empty succeed), so a
re-sent request is always safe. Each move goes out with the job's plan of it (the one it
was chosen by), which the planner schedules without planning it again.

The job owns three plain objects and decides what they report:

- its lanes (:class:`scara_collab.core.lanes.Lane`, one per arm that moves on its own);
- its request protocol (:class:`scara_collab.core.lanes.LaneProtocol`): it asks the moves and
  grips the job decides on, tracks their answers and deadlines, and reports each lane's
  outcome as a :class:`scara_collab.core.lanes.LaneEvent` (arrived, gripped, failed);
- its belt sharing (:class:`scara_collab.core.sharing.SharedBelt` in ``collaborative`` mode,
  :class:`scara_collab.core.sharing.SoloBelt` otherwise, chosen once): what each arm has
  booked, a chase timed around the other arm, how to unblock two arms that wait for each
  other, the follower's moves held for the leader's answer.

The decisions are the job's: which item an arm takes and when (ranked by
:func:`scara_collab.core.sorting.rank_by_cycle`), what follows each event, a mirrored pair kept
apart (:mod:`scara_collab.core.pairing`).
"""
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import line, pairing, sharing, sorting
from scara_collab.core.job_settings import JobSettings, MODES
from scara_collab.core.lanes import (Command, FAILED_MOVE, GripCommand, GripTrack, Lane,
                                     LaneEvent, LaneProtocol, MOVE_STATES, MoveCommand,
                                     MoveTrack, MOVING, PHASES, PlanFn, PlanMemo)
from scara_collab.core.model import CellModel
from scara_collab.core.sharing import SharedBelt, SoloBelt, Unblock
from scara_collab.core.trajectory import Trajectory

__all__ = ['Command', 'FAILED_MOVE', 'GripCommand', 'GripTrack', 'ItemNotes',
           'items_per_minute', 'JobSettings', 'Lane', 'LOOK_AGAIN', 'MODES', 'MOVE_STATES',
           'MoveCommand', 'MoveTrack', 'MOVING', 'PHASES', 'Picking', 'PICKING', 'SAVABLE',
           'SortingJob']

#: s an idle arm that found nothing to take waits before it looks again (the items move 2 cm)
LOOK_AGAIN = 0.1
#: urgent items an arm can still save by taking them first, most urgent first; with more, the
#: feed is faster than the arm and it takes the item that makes the shortest cycle
SAVABLE = 2


@dataclass(frozen=True)
class Picking:
    """How a mode chooses an arm's next item.

    ``own``: prefer items on the arm's half of the belt (None: the whole belt is its own);
    ``half``: take only items on the arm's half, and claim each one's mirror partner for the
    follower (mirrored pairs); ``by_cycle``: rank the candidates by cycle
    (:func:`scara_collab.core.sorting.rank_by_cycle`), else by urgency alone.
    """

    own: Optional[bool]
    half: bool
    by_cycle: bool


#: each mode's :class:`Picking`
PICKING = {'single': Picking(own=None, half=False, by_cycle=True),
           'collaborative': Picking(own=True, half=False, by_cycle=True),
           'mirrored': Picking(own=True, half=True, by_cycle=False)}


def items_per_minute(sorted_count: int, seconds: float) -> float:
    """Items sorted per minute over a window of ``seconds`` (0 for an empty window).

    The one definition used by the job's stats, the run summary and the benchmarks: the
    window starts when the feed starts (the job's start) and ends at the run's end.

    >>> items_per_minute(30, 60.0)
    30.0
    """
    return 60.0 * sorted_count / seconds if seconds > 0 else 0.0


class ItemNotes:
    """The job's last word on each item on the belt, so that a missed item says why.

    Kept per item until it leaves the belt: ranked among an arm's candidates, not met (no
    intercept, or the way not clear), claimed, given up.
    """

    def __init__(self):
        """No item noted yet."""
        self._notes: Dict[int, str] = {}

    def note(self, item: int, now: float, text: str) -> None:
        """Note ``text`` about ``item`` at sim time ``now``."""
        self._notes[item] = f'{text} at t={now:.2f} s'

    def ranked(self, robot: str, order: Sequence, now: float) -> None:
        """Note each item's place among ``robot``'s candidates (``(group, item)`` pairs)."""
        for k, (_, item) in enumerate(order):
            self.note(item.id, now, f'{robot} ranked it #{k + 1} of {len(order)}')

    def close(self, item: int) -> str:
        """Forget ``item`` (it left the belt); return the last note, or say there was none."""
        return self._notes.pop(item, 'never a candidate of either arm')


class SortingJob:
    """The sorting job's decisions (see the module docstring).

    :param cell: the cell model.
    :param settings: the tuning (:meth:`JobSettings.from_config`).
    :param plan: ``plan(robot, q_start, target) -> Trajectory`` with the planners' settings
        (raises ``ValueError`` if refused): the job times intercepts with the planners' own
        trajectories.
    :param log: ``log(level, text)`` for decisions worth a log line (``'info'``, ``'warn'``).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn,
                 log: Callable[[str, str], None] = lambda level, text: None):
        """Set up one lane per arm that moves on its own (one for a mirrored pair); not started."""
        self.cell, self.settings, self.log = cell, settings, log
        lead, foll = cell.leader, cell.follower
        specs = {'single': [(lead.name, (lead.name,))],
                 'collaborative': [(lead.name, (lead.name,)), (foll.name, (foll.name,))],
                 'mirrored': [(lead.name, (lead.name, foll.name))]}[settings.mode]
        #: the job's plans, each planned once per tick (every part of the job plans with it)
        self.plan = PlanMemo(plan)
        self.lanes: List[Lane] = [Lane(r, rs) for r, rs in specs]
        self.protocol = LaneProtocol(cell, settings, self.lanes, self.plan, log)
        self.belt = (SharedBelt if settings.mode == 'collaborative' else SoloBelt)(
            cell, settings, self.lanes, self.plan)
        self.picking = PICKING[settings.mode]
        used = {r for lane in self.lanes for r in lane.robots}
        self._unused = [a.name for a in cell.arms if a.name not in used]
        self._parked_unused = False
        self.running = False
        self.estop = False
        self.start_time: Optional[float] = None
        self.items: Dict[int, sorting.SeenItem] = {}
        self.claimed: Dict[int, str] = {}
        #: in a line of cells, the items this cell leaves for the ones downstream
        self.share = (line.Share(settings.line_cell, settings.line_cells, settings.line_capacity)
                      if settings.line_cells > 1 else None)
        self.counts: Dict[str, int] = {}
        self.sorted_by: Dict[str, int] = {a.name: 0 for a in cell.arms}
        self.give_ups = 0
        self.last_give_up = ''
        self.notes = ItemNotes()
        self._out: List[Command] = []

    # --- what the protocol knows ------------------------------------------------------------
    @property
    def q(self) -> Dict[str, np.ndarray]:
        """The arms' measured joints ``(3,)`` by name."""
        return self.protocol.q

    @property
    def retries(self) -> int:
        """Requests and gripper calls sent again so far."""
        return self.protocol.retries

    def phases(self) -> Dict[str, str]:
        """Each lane's phase, by its robot."""
        return self.protocol.phases()

    def lane(self, robot: str) -> Lane:
        """Return the lane that decides for ``robot``.

        :raises StopIteration: no lane does (the follower in ``single`` or ``mirrored`` mode).
        """
        return next(lane for lane in self.lanes if lane.robot == robot)

    # --- observations ---------------------------------------------------------------------
    def start(self, now: float) -> bool:
        """Run the job (idempotent); return False if it was already running."""
        if self.running:
            return False
        self.running = True
        if self.start_time is None:
            self.start_time = now
        return True

    def stop(self) -> bool:
        """Stop taking new items (idempotent); arms holding an item still bring it to its bin."""
        was, self.running = self.running, False
        return was

    def on_items(self, items: Sequence[sorting.SeenItem]) -> None:
        """Take the items resting on the belt now (not held, not falling, not in a bin)."""
        self.items = {it.id: it for it in items}
        if self.share is not None and self.items:
            self.share.see(self.items, max(it.stamp for it in items))

    def on_estop(self, on: bool) -> None:
        """Take the emergency stop: while set, nothing new is commanded."""
        self.estop = bool(on)

    def on_arm_state(self, robot: str, q: np.ndarray) -> None:
        """Take the measured joints of ``robot`` ``(3,)`` (finite, checked by the caller)."""
        self.protocol.on_arm_state(robot, q)

    def on_planner(self, robot: str, request: int, state: str, start: Optional[float],
                   end: Optional[float], reason: str = '') -> None:
        """Take a planner status about ``robot``'s move for ``request`` (others are ignored)."""
        timed = self.protocol.on_planner(robot, request, state, start, end, reason)
        if timed is not None:
            self.belt.timed(robot, request, timed, self.q)

    def on_execution(self, robot: str, request: int, state: str, start: Optional[float],
                     end: Optional[float], reason: str = '', late: Optional[float] = None) -> None:
        """Take a bridge execution status about ``robot``'s move for ``request``.

        :param late: s an ``accepted`` move starts after the start it asked for (None: it
            asked for none, or not known).
        """
        timed = self.protocol.on_execution(robot, request, state, start, end, reason, late)
        if timed is not None:
            self.belt.timed(robot, request, timed, self.q)

    def on_trajectory(self, robot: str, move_id: str, request: Optional[int], stamp: float,
                      t: np.ndarray, q: np.ndarray) -> None:
        """Take a trajectory ``robot`` was sent: a planner's move of the job's, or any other.

        With two lanes the arm is committed to it (the belt's booking, by the committed-motion
        model's rules; the bridge's statuses correct it: :meth:`on_arm_status`).

        :param move_id: its name; :param request: the job's request it answers, or None (a
            raw command, a hold); :param stamp: its start, s (0: now); :param t: ``(N,)`` s
            from its start; :param q: ``(N, 3)`` joint positions.
        """
        track = None if request is None else self.protocol.open_track(robot, request)
        self.belt.on_trajectory(robot, move_id, track, stamp, t, q, self.protocol.now, self.q)

    def on_arm_status(self, robot: str, state: str, move_id: str,
                      start: Optional[float] = None) -> None:
        """Take the bridge's status of any move of ``robot`` (what the arm is committed to)."""
        self.belt.on_status(robot, state, move_id, start, self.protocol.now, self.q)

    def on_grip(self, token: int, ok: bool, message: str = '') -> None:
        """Take a gripper response for request ``token``: any attempt of a grip still open."""
        self.protocol.on_grip(token, ok, message)

    def on_item_event(self, kind: str, item: int, robot: str) -> None:
        """Count a bridge item event; it also confirms grasps and releases."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind == 'sorted' and robot in self.sorted_by:
            self.sorted_by[robot] += 1
        if kind in sorting.GONE:
            self.claimed.pop(item, None)
            last = self.notes.close(item)
            if kind == 'missed':
                self.log('warn', f'item {item} missed; last: {last}')
        self.protocol.confirm_grip(kind, robot)

    # --- the clock ------------------------------------------------------------------------
    def tick(self, now: float) -> List[Command]:
        """Advance every lane to ``now`` (sim s); return the commands to send, in order.

        Each lane in turn: an idle one picks its next item; a waiting one is advanced by the
        protocol, and the event that ends its wait (:class:`~scara_collab.core.lanes.LaneEvent`)
        is decided on here. Then the belt sharing may unblock an arm that waits for the other,
        and holds the follower's moves until the leader's planner has answered.
        """
        self._out = []
        self.protocol.now = now
        self.plan.forget()
        if self.estop or not self.protocol.knows_every_arm():
            self.belt.drop_held()  # nothing new is commanded; a lane re-sends after answer_timeout
            return []
        if self.running and not self._parked_unused:
            self._park_unused(now)
        for lane in self.lanes:
            if lane.phase == 'idle':
                if self.running and now >= lane.next_look:
                    self._pick_next(lane, now)
                continue
            sent, event = self.protocol.tick(lane, now)
            self._out += sent
            if event is not None:
                self._decide(event, now)
        self._unblock(self.belt.unblock(now, self.q), now)
        return self.belt.in_turn(self._out, now)

    def chase(self, robot: str, item: sorting.SeenItem, now: float) -> List[MoveCommand]:
        """Send ``robot``'s lane after ``item`` now, as a pick would (the item is not claimed).

        :return: the moves asked, in order (the caller sends them); ``[]`` if the arm cannot
            meet the item (or not without waiting for the other arm's booked move).
        """
        self._out = []
        return list(self._out) if self._chase(self.lane(robot), item, now) else []

    def park(self, robot: str, now: float) -> List[MoveCommand]:
        """Send ``robot``'s lane to wait clear of the shared zone; return the moves asked."""
        self._out = []
        self._park(self.lane(robot), now)
        return list(self._out)

    def _decide(self, event: LaneEvent, now: float) -> None:
        if event.kind == 'arrived':
            self._arrived(event.lane, now)
        elif event.kind == 'gripped':
            self._gripped(event.lane, now)
        else:
            self._give_up(event.lane, now, event.why)

    # --- asking ------------------------------------------------------------------------------
    def _move(self, lane: Lane, phase: str, target, start: float, now: float,
              traj: Optional[Trajectory] = None) -> None:
        """Ask for ``lane``'s move (:meth:`LaneProtocol.move`) and book it on the belt."""
        self._out.append(self.protocol.move(lane, phase, target, start, now, traj))
        self.belt.asked(lane)

    def _grip(self, lane: Lane, grasp: bool, now: float) -> None:
        self._out += self.protocol.grip(lane, grasp, now)

    def _asap_start(self, lane: Lane, now: float) -> float:
        return self.protocol.asap_start(lane, now)

    # --- after a move -----------------------------------------------------------------------
    def _arrived(self, lane: Lane, now: float) -> None:
        if lane.phase == 'to_park':
            lane.idle()
        elif lane.phase == 'to_bin':
            self._grip(lane, False, now)
        elif lane.phase == 'lift':
            self._to_bin(lane, now)
        elif lane.phase == 'via':
            if lane.route:  # the next leg of a detour
                phase, target = lane.route.pop(0)
                self._move(lane, phase, target, self._asap_start(lane, now), now)
            elif lane.holding:
                self._to_bin(lane, now)
            elif not self._chase(lane, self.items.get(lane.item.id, lane.item), now):
                self._give_up(lane, now, f'item {lane.item.id} got away (after a detour)')
        else:  # at the item? a late start (the arm yielded) leaves it short of the item
            seen = self.items.get(lane.item.id)
            if seen is None:
                return self._give_up(lane, now, f'item {lane.item.id} is no longer on the belt')
            # where the item will be when the grasp takes hold (the gripper call's latency)
            off = sorting.predict(self.cell, seen, now + self.protocol.grasp_lead)[:2] \
                - lane.target[:2]
            if np.hypot(*off) <= self.settings.grasp_reach:
                self._grip(lane, True, now)
            elif not self._chase(lane, seen, now):
                self._give_up(lane, now, f'item {seen.id} got away ({np.hypot(*off):.3f} m)')

    def _chase(self, lane: Lane, item: sorting.SeenItem, now: float) -> bool:
        """Ask for the move that meets ``item``; return False if the arm cannot."""
        s = self.settings
        # a mirrored pair's move takes one hop more (the replication manager) to both planners
        start = now + s.decision_lead + (s.pair_lead if lane.mirrored else 0.0)
        arm = self.cell.arm(lane.robot)
        q0 = self.q[lane.robot]
        aim = pairing.pair_aim(self.cell, item, s.pair_offset) if lane.mirrored else item
        lead = self.protocol.grasp_lead
        hit = sorting.intercept(self.cell, arm, q0, aim, start, s.pick_z,
                                lambda q, p: self.plan(lane.robot, q, p), lead=lead)
        if hit is not None:
            hit = self.belt.unhindered(lane, aim, hit, now, self.q, lead)
        if hit is None:
            return False
        lane.item = item
        if lane.mirrored and not pairing.pair_clear(self.cell, lane.robot, hit.traj,
                                                    s.pair_margin):
            route = pairing.detour(self.cell, self.plan, lane.robot, q0, hit.target,
                                   s.carry_z, s.pair_margin)
            if route:  # go round first, then meet the item from there
                self._move(lane, 'via', route[0], start, now)
                lane.route = [('via', p) for p in route[1:]]
                return True
        self._move(lane, 'to_item', hit.target, hit.start, now, hit.traj)
        return True

    def _to_bin(self, lane: Lane, now: float) -> None:
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls,
                                  self.settings.drop_clearance)
        self._move_safely(lane, 'to_bin', drop, self._asap_start(lane, now), now)

    def _move_safely(self, lane: Lane, phase: str, target, start: float, now: float) -> None:
        """Ask for a move like :meth:`_move`; a mirrored pair may go round by a waypoint.

        A pair that would come within the planners' margin goes round, so the follower need
        not yield and both arms start together.
        """
        if lane.mirrored:
            q0 = self.q[lane.robot]
            margin = self.settings.pair_margin
            try:
                clear = pairing.pair_clear(self.cell, lane.robot,
                                           self.plan(lane.robot, q0, target), margin)
            except ValueError:
                clear = True  # the planner will refuse it with the reason
            route = [] if clear else pairing.detour(self.cell, self.plan, lane.robot, q0,
                                                    target, self.settings.carry_z, margin)
            if route:
                lane.route = [('via', p) for p in route[1:]] + [(phase, np.asarray(target))]
                self._move(lane, 'via', route[0], start, now)
                return
        self._move(lane, phase, target, start, now)

    # --- picking --------------------------------------------------------------------------
    def _pick_next(self, lane: Lane, now: float) -> None:
        s, how = self.settings, self.picking
        arm = self.cell.arm(lane.robot)
        others_busy = any(o.phase != 'idle' for o in self.lanes if o is not lane)
        free = [it for i, it in self.items.items()
                if i not in self.claimed and lane.failures.get(i, 0) < 2
                and (self.share is None or self.share.takes(i, now))]
        if how.half:  # the leader takes its half; the partner is mirrored
            side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
            free = [it for it in free if np.sign(it.position[1]) == side]
        order = sorting.order_candidates(self.cell, arm, free, now + s.decision_lead,
                                         s.pick_z, how.own, steal=others_busy,
                                         other_cycle=s.steal_cycle or None, groups=True)
        if how.by_cycle:  # the shortest cycles first, urgent savable items first
            order = sorting.rank_by_cycle(self.cell, arm, self.q[lane.robot], order,
                                          now + s.decision_lead, s.pick_z,
                                          s.drop_clearance, sharing.URGENT_SLACK, SAVABLE)
        self.notes.ranked(lane.robot, order, now)
        for item in [it for _, it in order[:2]]:
            if not self._chase(lane, item, now):
                self.notes.note(item.id, now, f'{lane.robot} could not meet it (or not yet)')
                continue
            self.notes.note(item.id, now, f'{lane.robot} chased it')
            self.claimed[item.id] = lane.robot
            if how.half:
                partner = sorting.mirror_partner(self.cell, item, list(self.items.values()))
                if partner is not None:
                    self.claimed[partner.id] = self.cell.follower.name
            return
        lane.next_look = now + LOOK_AGAIN  # each look plans: not at every tick

    # --- after a grip -----------------------------------------------------------------------
    def _gripped(self, lane: Lane, now: float) -> None:
        s = self.settings
        main = lane.grips[lane.robot]
        for robot, track in lane.grips.items():
            if robot != lane.robot and not track.ok:
                self.log('warn', f'{robot} gripper: {track.message}')
        if lane.phase == 'releasing':
            if lane.item is not None:
                self.claimed.pop(lane.item.id, None)
            if not main.ok:
                self.log('warn', f'{lane.robot}: release failed ({main.message})')
            lane.idle()
        elif not main.ok:
            item = lane.item
            lane.failures[item.id] = lane.failures.get(item.id, 0) + 1
            self.claimed.pop(item.id, None)
            self.log('info', f'{lane.robot}: grasp of item {item.id} failed ({main.message})')
            lane.idle()
        elif s.carry_z > s.pick_z + 1e-6 and self._would_sweep(lane, now):
            up = np.array([lane.target[0], lane.target[1], s.carry_z])
            lane.bin_tries, lane.holding = 0, True
            self._move(lane, 'lift', up, self._asap_start(lane, now), now)
        else:
            lane.bin_tries, lane.holding = 0, True
            self._to_bin(lane, now)

    def _would_sweep(self, lane: Lane, now: float) -> bool:
        """Return True if the item just grasped would touch an item on the belt on its way.

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
            traj = self.plan(lane.robot, self.q[lane.robot], drop)
        except ValueError:
            return True
        others = [it for it in self.items.values() if it.id != lane.item.id]
        spare = s.carry_z - s.pick_z - self.cell.item_size  # = carry_clearance
        return bool(others) and sorting.carry_sweeps(
            self.cell, traj.p, self._asap_start(lane, now) + traj.t, others, s.pick_z, spare,
            mirrored=lane.mirrored, late=self.protocol.start_lag.worst)

    # --- out of the way ---------------------------------------------------------------------
    def _park(self, lane: Lane, now: float) -> None:
        """Wait clear of the shared zone, above the first bin, so the other arm is free."""
        park = sorting.drop_point(self.cell, lane.robot, self.cell.item_classes[0],
                                  self.settings.drop_clearance)
        self._move_safely(lane, 'to_park', park, self._asap_start(lane, now), now)

    def _park_unused(self, now: float) -> None:
        """Arms no lane uses wait above their first bin, off the belt (once)."""
        self._parked_unused = True
        for robot in self._unused:
            park = sorting.drop_point(self.cell, robot, self.cell.item_classes[0],
                                      self.settings.drop_clearance)
            self._out.append(self.protocol.move_once(
                robot, park, now + self.settings.decision_lead, 'park'))

    def _unblock(self, how: Optional[Unblock], now: float) -> None:
        """Do what the belt sharing asks for an arm that waits for the other (or nothing)."""
        if how is None:
            return
        lane = how.lane
        if how.action == 'park':
            self.log('info', f'{lane.robot}: parks to clear the way for {how.other.robot}')
            self._park(lane, now)
        elif how.action == 'reaim':
            self._aim_elsewhere(lane, how.other, now)
        elif how.action == 'give_way':
            self._give_up(lane, now, how.why)
        else:  # back out to the waypoint, then on to the bin
            drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls,
                                      self.settings.drop_clearance)
            self.log('info', f'{lane.robot}: both arms hold items and wait for each other: '
                     f'{lane.robot} backs out to y={how.via[1]:.2f} first')
            lane.route = [('to_bin', drop)]
            self._move(lane, 'via', how.via, self._asap_start(lane, now), now)

    def _aim_elsewhere(self, lane: Lane, other: Lane, now: float) -> None:
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

    # --- endings --------------------------------------------------------------------------
    def _give_up(self, lane: Lane, now: float, why: str) -> None:
        self.log('warn', f'{lane.robot}: {why}')
        self.give_ups += 1
        self.last_give_up = f't={now:.2f} s {lane.robot} {lane.phase}: {why}'
        if lane.item is not None:
            self.notes.note(lane.item.id, now, f'{lane.robot} gave it up ({why})')
        phase = lane.phase
        lane.route = []
        if lane.holding and phase in MOVING:  # never put an item down off the bin
            lane.bin_tries += 1
            if lane.bin_tries <= self.settings.bin_retries:
                self._to_bin(lane, now)
                return
            self.log('warn', f'{lane.robot}: releasing item {lane.item.id} where it is after '
                     f'{lane.bin_tries} bin moves')
            self._grip(lane, False, now)
            return
        if lane.item is not None:
            self.claimed.pop(lane.item.id, None)
            lane.failures[lane.item.id] = lane.failures.get(lane.item.id, 0) + 1
        lane.idle()
        if phase == 'to_park':  # the park move itself failed: stay idle, do not loop
            return
        self._park(lane, now)

    # --- figures --------------------------------------------------------------------------
    def minutes(self, now: float) -> float:
        """Minutes since the job started (0 before)."""
        return 0.0 if self.start_time is None else max(0.0, now - self.start_time) / 60.0

    def rate(self, now: float) -> float:
        """Items sorted per minute since the job started (:func:`items_per_minute`)."""
        return items_per_minute(self.counts.get('sorted', 0), self.minutes(now) * 60.0)
