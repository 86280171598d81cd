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
re-sent request is always safe.

Move requests are identified by their requested start in integer nanoseconds
(:mod:`scara_collab.nodes.protocol` carries that id through planner and bridge); the job keeps
them unique per arm.
"""
from dataclasses import dataclass, field
import math
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.core import collision, planning, sorting
from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_joints, mirror_point
from scara_collab.core.model import CellModel
from scara_collab.core.trajectory import Trajectory

MODES = ('single', 'collaborative', 'mirrored')
PHASES = ('idle', 'to_item', 'grasping', 'lift', 'via', 'to_bin', 'releasing', 'to_park')
MOVING = ('to_item', 'lift', 'via', 'to_bin', 'to_park')
#: m: waypoints a mirrored pair may take to stay apart: this far out from the belt centre line
VIA_OFFSETS = (0.6, 0.9, 1.2)
#: s an idle arm that found nothing to take waits before it looks again (the items move 2 cm)
LOOK_AGAIN = 0.1
#: s: an item with less than this left in an arm's reach is urgent: about two cycles, so of
#: two urgent items the arm can still take the one after the other. An urgent item is chased
#: even when the other arm's booked move will hold the arm up (else the arm may take another
#: first and come back too late, or both arms may defer it until it is missed)
URGENT_SLACK = 8.0
#: urgent items an arm can still save by taking them first, most urgent first; with more, the
#: feed is faster than the arm and it takes the item that makes the shortest cycle
SAVABLE = 2
#: how many candidates (most urgent first) an idle arm compares
CANDIDATES = 6
#: planner / bridge answers about a move, in the order a move goes through them
MOVE_STATES = ('asked', 'queued', 'waiting', 'planned', 'accepted', 'finished')
FAILED_MOVE = ('refused', 'superseded', 'held')

PlanFn = Callable[[str, np.ndarray, np.ndarray], Trajectory]


def items_per_minute(sorted_count: int, seconds: float) -> float:
    """Items sorted per minute over a window of ``seconds`` (0 for an empty window).

    The one definition used by the job's stats, the run summary and the benchmarks: the
    window starts when the feed starts (the job's start) and ends at the run's end.

    >>> items_per_minute(30, 60.0)
    30.0
    """
    return 60.0 * sorted_count / seconds if seconds > 0 else 0.0


@dataclass(frozen=True)
class JobSettings:
    """The job's tuning, from ``config/automation.yaml`` (see that file for the meanings)."""

    mode: str
    pick_z: float
    carry_z: float
    drop_clearance: float
    grasp_reach: float
    decision_lead: float
    answer_timeout: float
    answer_retries: int
    move_timeout: float
    carry_timeout: float
    arrive_timeout: float
    arrive_tolerance: float
    grip_timeout: float
    grip_retries: int
    pair_offset: float = 0.0
    pair_margin: float = 0.13
    pair_lead: float = 0.1
    unblock_after: float = 0.5
    bin_retries: int = 3
    steal_cycle: float = 0.0

    @staticmethod
    def from_config(cell: CellModel, cfg: dict, mode: Optional[str] = None,
                    planning_buffer: float = 0.03) -> 'JobSettings':
        """Build the settings from the ``automation`` config tree (``mode`` overrides).

        :param planning_buffer: ``controllers.yaml`` ``planning_buffer``: mirrored pairs are
            checked against the planners' margin (safety margin + this).
        """
        mode = mode or cfg['mode']
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        pick_z = sorting.pick_height(cell, cfg['pick_clearance'])
        # a held item hangs item_size + pick_clearance below the tool: lifted to carry_z, its
        # bottom clears the tops of the items on the belt by carry_clearance
        carry_z = (pick_z + cell.item_size + float(cfg['carry_clearance'])
                   if cfg['lift_after_grasp'] else pick_z)
        return JobSettings(
            mode=mode, pick_z=pick_z, carry_z=carry_z,
            drop_clearance=float(cfg['drop_clearance']), grasp_reach=float(cfg['grasp_reach']),
            decision_lead=float(cfg['decision_lead']),
            answer_timeout=float(cfg['answer_timeout']), answer_retries=int(cfg['answer_retries']),
            move_timeout=float(cfg['move_timeout']), carry_timeout=float(cfg['carry_timeout']),
            arrive_timeout=float(cfg['arrive_timeout']),
            arrive_tolerance=float(cfg['arrive_tolerance']),
            grip_timeout=float(cfg['grip_timeout']), grip_retries=int(cfg['grip_retries']),
            pair_offset=float(cfg['mirror_pair_offset']),
            pair_lead=float(cfg['mirror_start_lead']),
            unblock_after=float(cfg['unblock_after']),
            steal_cycle=float(cfg['steal_cycle']),
            pair_margin=cell.safety_margin + float(planning_buffer))


@dataclass(frozen=True)
class MoveCommand:
    """Ask the planner(s) for a move: ``robot``'s tool to ``target`` (world), from ``start``.

    ``mirrored``: send it to the replication manager (``/collab/target``), which moves the
    follower to the mirror image with the same request. ``request`` (ns) is the target's
    stamp and the move's identity; a re-sent request has the same one.
    """

    robot: str
    target: np.ndarray
    request: int
    mirrored: bool
    purpose: str

    @property
    def start(self) -> float:
        """The requested start, s."""
        return self.request * 1e-9


@dataclass(frozen=True)
class GripCommand:
    """Call ``robot``'s gripper: ``grasp`` true = grasp, false = release; answer with ``token``."""

    robot: str
    grasp: bool
    token: int


@dataclass
class MoveTrack:
    """What is known of one arm's move of the current request."""

    state: str = 'asked'
    since: float = 0.0  # when it entered this state (for 'waiting')
    start: Optional[float] = None
    end: Optional[float] = None
    reason: str = ''
    arrived: bool = False
    #: the motion it commits to (the job's own plan of it, from its start), once timed
    timeline: Optional[planning.Timeline] = None


@dataclass
class GripTrack:
    """One gripper request: its token, when it was sent, how often, its outcome."""

    token: int
    sent: float
    attempts: int = 1
    ok: Optional[bool] = None
    message: str = ''


@dataclass
class Lane:
    """One arm's work (both arms' in mirrored mode); see the module docstring."""

    robot: str
    robots: Tuple[str, ...]
    phase: str = 'idle'
    item: Optional[sorting.SeenItem] = None
    target: Optional[np.ndarray] = None
    request: int = 0
    purpose: str = ''
    since: float = 0.0
    sent: float = 0.0
    sends: int = 0
    moves: Dict[str, MoveTrack] = field(default_factory=dict)
    grips: Dict[str, GripTrack] = field(default_factory=dict)
    bin_tries: int = 0
    reaims: int = 0
    holding: bool = False
    route: List[Tuple[str, np.ndarray]] = field(default_factory=list)
    failures: Dict[int, int] = field(default_factory=dict)
    next_look: float = 0.0  # idle with nothing to take: look again from then


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
        self.cell, self.s, self.plan, self.log = cell, settings, plan, log
        lead, foll = cell.leader, cell.follower
        robots = {'single': [(lead.name, (lead.name,))],
                  'collaborative': [(lead.name, (lead.name,)), (foll.name, (foll.name,))],
                  'mirrored': [(lead.name, (lead.name, foll.name))]}[settings.mode]
        self.lanes = [Lane(r, rs) for r, rs in robots]
        self.running = False
        self.estop = False
        self.start_time: Optional[float] = None
        self.q: Dict[str, np.ndarray] = {}
        self.items: Dict[int, sorting.SeenItem] = {}
        self.claimed: Dict[int, str] = {}
        self.counts: Dict[str, int] = {}
        self.sorted_by: Dict[str, int] = {a.name: 0 for a in cell.arms}
        self.give_ups = 0
        self.retries = 0
        self.last_give_up = ''
        self._last_request: Dict[str, int] = {a.name: 0 for a in cell.arms}
        self._token = 0
        self._parked_unused = False
        self._out: List[object] = []
        self._now = 0.0

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

    def on_arm_state(self, robot: str, q: np.ndarray) -> None:
        """Take the measured joints of ``robot`` ``(3,)`` (finite, checked by the caller)."""
        self.q[robot] = np.asarray(q, dtype=float)

    def on_items(self, items: Sequence[sorting.SeenItem]) -> None:
        """Take the items resting on the belt now (not held, not falling, not in a bin)."""
        self.items = {it.id: it for it in items}

    def on_estop(self, on: bool) -> None:
        """Take the emergency stop: while set, nothing new is commanded."""
        self.estop = bool(on)

    def on_item_event(self, kind: str, item: int, robot: str) -> None:
        """Count a bridge item event; it also and it confirms grasps and releases."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind == 'sorted' and robot in self.sorted_by:
            self.sorted_by[robot] += 1
        if kind in ('sorted', 'wrong_bin', 'missed', 'dropped'):
            self.claimed.pop(item, None)
        phase = {'grasped': 'grasping', 'released': 'releasing'}.get(kind)
        for lane in self.lanes:  # the bridge saw it happen: the response may be lost
            track = lane.grips.get(robot)
            if lane.phase == phase and track is not None and track.ok is None:
                track.ok, track.message = True, f'{kind} event'

    def on_planner(self, robot: str, request: int, state: str, start: Optional[float],
                   end: Optional[float], reason: str = '') -> None:
        """Take a planner status about ``robot``'s move for ``request`` (others are ignored)."""
        track = self._track(robot, request)
        if track is None or track.state in ('finished',) + FAILED_MOVE:
            return
        if state == 'planned':
            if track.state == 'accepted' and abs(start - track.start) < 1e-6:
                return  # the bridge already runs it (its start is the one that counts)
            track.state, track.start, track.end = 'planned', start, end
            self._book(robot, request, track)
        elif state in ('queued', 'waiting'):  # not (or no longer) committed
            if track.state != state:
                track.since = self._now
            track.state, track.start, track.end = state, None, None
        elif state in ('refused', 'superseded'):
            track.state, track.reason = state, reason

    def on_execution(self, robot: str, request: int, state: str, start: Optional[float],
                     end: Optional[float], reason: str = '') -> None:
        """Take a bridge execution status about ``robot``'s move for ``request``."""
        track = self._track(robot, request)
        if track is None or track.state in ('finished',) + FAILED_MOVE:
            return
        if state == 'accepted':
            track.state, track.start, track.end = 'accepted', start, end
            self._book(robot, request, track)
        elif state == 'finished':
            track.state = 'finished'
        elif state == 'preempted':  # the planner took it back (it says what comes next)
            track.state, track.start, track.end = 'waiting', None, None
        elif state in ('refused', 'held'):
            track.state, track.reason = state, reason or state

    def on_grip(self, token: int, ok: bool, message: str = '') -> None:
        """Take a gripper response for request ``token`` (late or unknown tokens: ignored)."""
        for lane in self.lanes:
            for track in lane.grips.values():
                if track.token == token and track.ok is None:
                    track.ok, track.message = bool(ok), message

    def _book(self, robot: str, request: int, track: MoveTrack) -> None:
        """Keep the motion a timed move commits ``robot`` to (collaborative look-ahead).

        The job plans the move itself, as the planner did, from where the arm is when the
        move is first timed (it has not started yet); a later start only shifts it.
        """
        if len(self.lanes) < 2 or track.start is None:
            return
        if track.timeline is not None:
            shift = track.start - track.timeline.start
            track.timeline = planning.Timeline(track.timeline.t + shift, track.timeline.q)
            return
        lane = next(la for la in self.lanes if la.request == request and robot in la.moves)
        try:
            traj = self.plan(robot, self.q[robot], self._target_of(lane, robot))
        except (ValueError, KeyError):
            return
        track.timeline = planning.Timeline.of(traj, track.start)

    def _committed(self, robot: str, now: float) -> planning.Timeline:
        """Return ``robot``'s motion from ``now`` as far as it is booked (else it holds)."""
        for lane in self.lanes:
            track = lane.moves.get(robot) if lane.phase in MOVING else None
            if (track is not None and track.timeline is not None
                    and track.state in ('planned', 'accepted') and track.timeline.end > now):
                return track.timeline
        return planning.Timeline.hold(now, self.q[robot])

    def _track(self, robot: str, request: int) -> Optional[MoveTrack]:
        for lane in self.lanes:
            if lane.phase in MOVING and lane.request == request and robot in lane.moves:
                return lane.moves[robot]
        return None

    # --- the clock ------------------------------------------------------------------------
    def tick(self, now: float) -> List[object]:
        """Advance every lane to ``now`` (sim s); return the commands to send, in order."""
        self._out = []
        self._now = now
        if self.estop or len(self.q) < len(self.cell.arms):
            return self._out
        if self.running and not self._parked_unused:
            self._park_unused(now)
        for lane in self.lanes:
            if lane.phase == 'idle':
                if self.running and now >= lane.next_look:
                    self._pick_next(lane, now)
            elif lane.phase in MOVING:
                self._tick_move(lane, now)
            else:
                self._tick_grip(lane, now)
        if len(self.lanes) > 1:
            self._unblock(now)
        return self._out

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
            elif self._blocked(other, now):
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
        """Back an arm holding an item out of the shared zone, away from the other arm.

        The waypoint is straight out from the belt on the arm's own side (``VIA_OFFSETS``
        from the centre line, at carry height) and further out than the tool is now (so a
        retreat that did not clear the way is followed by one further out); the first whose
        leg keeps the planners' margin from the other arm where it stands is taken, then the
        bin. Return False if none does (then the other arm backs out).
        """
        arm = self.cell.arm(lane.robot)
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        q0, q_other = self.q[lane.robot], self.q.get(other.name)
        if q_other is None:
            return False
        start = fk(arm, q0)
        side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
        for off in VIA_OFFSETS:
            via = np.array([start[0], self.cell.belt.centre_y + side * off,
                            max(start[2], self.s.carry_z)])
            if side * (via[1] - start[1]) < 0.05:
                continue  # out there already (an earlier retreat did not clear the way)
            try:
                leg = self.plan(lane.robot, q0, via)
            except ValueError:
                continue
            if np.min(collision.arm_distance(arm, leg.q, other, q_other)) < self.s.pair_margin:
                continue
            drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls,
                                      self.s.drop_clearance)
            self.log('info', f'{lane.robot}: both arms hold items and wait for each other: '
                     f'{lane.robot} backs out to y={via[1]:.2f} first')
            lane.route = [('to_bin', drop)]
            self._move(lane, 'via', via, self._soon(lane, now), now)
            return True
        return False

    def phases(self) -> Dict[str, str]:
        """Each lane's phase, by its robot."""
        return {lane.robot: lane.phase for lane in self.lanes}

    # --- moves ----------------------------------------------------------------------------
    def _request(self, robots: Sequence[str], start: float) -> int:
        req = max([int(round(start * 1e9))] + [self._last_request[r] + 1 for r in robots])
        for r in robots:
            self._last_request[r] = req
        return req

    def _move(self, lane: Lane, phase: str, target, start: float, now: float) -> None:
        lane.phase, lane.target = phase, np.asarray(target, dtype=float)
        lane.request = self._request(lane.robots, max(start, now + 1e-3))
        lane.moves = {r: MoveTrack() for r in lane.robots}
        lane.since = lane.sent = now
        lane.sends = 1
        self._send(lane)

    def _soon(self, lane: Lane, now: float) -> float:
        """Return the start to ask for a move that should start as soon as possible.

        One arm: now (its planner adds its own planning lead). A mirrored pair: ``pair_lead``
        ahead, so both planners get a start that is still in the future and plan the same.
        """
        return now + (self.s.pair_lead if len(lane.robots) > 1 else 1e-3)

    def _send(self, lane: Lane) -> None:
        self._out.append(MoveCommand(lane.robot, lane.target, lane.request,
                                     len(lane.robots) > 1, lane.phase))

    def _target_of(self, lane: Lane, robot: str) -> np.ndarray:
        if robot == lane.robot:
            return lane.target
        return mirror_point(self.cell.arm(lane.robot), self.cell.arm(robot), lane.target)

    def _at_target(self, lane: Lane, robot: str) -> bool:
        q = self.q.get(robot)
        if q is None:
            return False
        tip = fk(self.cell.arm(robot), q)
        return float(np.linalg.norm(tip - self._target_of(lane, robot))) <= \
            self.s.arrive_tolerance

    def _tick_move(self, lane: Lane, now: float) -> None:
        limit = self.s.carry_timeout if lane.holding else self.s.move_timeout
        for robot, track in lane.moves.items():
            if track.arrived:
                continue
            if track.state in FAILED_MOVE:
                return self._give_up(lane, now, f'{robot} move {track.state}: {track.reason}')
            if track.state == 'finished':
                track.arrived = True
                continue
            if track.state == 'asked' and now - lane.sent > self.s.answer_timeout:
                if lane.sends > self.s.answer_retries:
                    return self._give_up(lane, now, f'no answer from the {robot} planner '
                                         f'after {lane.sends} requests')
                lane.sends += 1
                lane.sent = now
                self.retries += 1
                self.log('info', f'{robot}: no planner answer for request {lane.request} in '
                         f'{self.s.answer_timeout:g} s; asking again ({lane.sends})')
                self._send(lane)
                continue
            if track.end is None:  # asked, queued or waiting
                if now - lane.since > limit:
                    others = ', '.join(f'{o.robot} {o.phase}' + (' holding' if o.holding else '')
                                       for o in self.lanes if o is not lane)
                    return self._give_up(lane, now, f'no plan from the {robot} planner in '
                                         f'{limit:g} s ({track.state}'
                                         + (f'; {others})' if others else ')'))
                continue
            if now >= track.end and self._at_target(lane, robot):
                track.arrived = True
            elif now > track.end + self.s.arrive_timeout:
                return self._give_up(lane, now, f'{robot} did not arrive within '
                                     f'{self.s.arrive_timeout:g} s of its end ({track.state})')
        if all(t.arrived for t in lane.moves.values()):
            self._arrived(lane, now)

    def _arrived(self, lane: Lane, now: float) -> None:
        if lane.phase == 'to_park':
            self._idle(lane)
        elif lane.phase == 'to_bin':
            self._grip(lane, False, now)
        elif lane.phase == 'lift':
            self._to_bin(lane, now)
        elif lane.phase == 'via':
            if lane.route:  # the next leg of a mirrored pair's detour
                phase, target = lane.route.pop(0)
                self._move(lane, phase, target, self._soon(lane, now), now)
            elif lane.holding:
                self._to_bin(lane, now)
            elif not self._chase(lane, self.items.get(lane.item.id, lane.item), now):
                self._give_up(lane, now, f'item {lane.item.id} got away (after a detour)')
        else:  # at the item? a late start (the arm yielded) leaves it short of the item
            seen = self.items.get(lane.item.id)
            if seen is None:
                return self._give_up(lane, now, f'item {lane.item.id} is no longer on the belt')
            off = sorting.predict(self.cell, seen, now)[:2] - lane.target[:2]
            if math.hypot(*off) <= self.s.grasp_reach:
                self._grip(lane, True, now)
            elif not self._chase(lane, seen, now):
                self._give_up(lane, now, f'item {seen.id} got away ({math.hypot(*off):.3f} m)')

    def _aim(self, item: sorting.SeenItem) -> sorting.SeenItem:
        """Return where the tool meets ``item``.

        In mirrored mode that is at least ``pair_offset`` from the belt centre line (within
        grasp reach), so the two mirrored tools keep the planners' margin and the follower
        never has to yield: both start together.
        """
        if len(self.lanes[0].robots) < 2:
            return item
        centre = self.cell.belt.centre_y
        dy = item.position[1] - centre
        if abs(dy) >= self.s.pair_offset:
            return item
        side = np.sign(self.cell.leader.base_position[1] - centre)
        aim = item.position.copy()
        aim[1] = centre + side * self.s.pair_offset
        return sorting.SeenItem(item.id, item.cls, aim, item.stamp)

    def _chase(self, lane: Lane, item: sorting.SeenItem, now: float) -> bool:
        start = now + self.s.decision_lead
        arm = self.cell.arm(lane.robot)
        q0 = self.q[lane.robot]
        hit = sorting.intercept(self.cell, arm, q0, self._aim(item), start,
                                self.s.pick_z, lambda q, p: self.plan(lane.robot, q, p))
        if hit is not None and len(self.lanes) > 1:
            hit = self._unhindered(lane, item, hit, now)
        if hit is None:
            return False
        lane.item = item
        if len(lane.robots) > 1 and not self._pair_clear(lane.robot, hit.traj):
            route = self._detour(lane.robot, q0, hit.target)
            if route:  # go round first, then meet the item from there
                self._move(lane, 'via', route[0], start, now)
                lane.route = [('via', p) for p in route[1:]]
                return True
        self._move(lane, 'to_item', hit.target, hit.start, now)
        return True

    def _unhindered(self, lane: Lane, item: sorting.SeenItem, hit: sorting.Intercept,
                    now: float) -> Optional[sorting.Intercept]:
        """Return an intercept timed around the other arm's booked motion, or None.

        The shared zone booked in time (collaborative): the chase is scheduled against the
        other arm's committed move (:func:`scara_collab.core.planning.schedule`, with the
        planners' margin), first booked, first served: the leader too respects a move the
        follower has already booked, though its planner would make the follower yield (it
        does when a conflict comes anyway: the priority rule stays the planners' safety). If
        the chase would have to wait longer than the item takes to move half the grasp
        reach, the item is met later, from where the arm waits, so the tool arrives where the
        item will be then. An item with more than ``URGENT_SLACK`` left in reach is deferred
        (None: the arm takes another) when even that is held up or the item would get away
        meanwhile. An urgent one is never deferred for a long wait: the arm goes for it and
        waits if it must (in an hour's soak both arms deferred one item until it was missed);
        None only when the delayed meeting is out of this arm's reach (the other arm may still
        save it: in another soak an arm chased such an item on the un-delayed time, arrived
        late and lost it).
        """
        arm = self.cell.arm(lane.robot)
        other = next(a for a in self.cell.arms if a.name != lane.robot)
        if other.name not in self.q:
            return hit
        p = sorting.predict(self.cell, item, now)
        urgent = sorting.time_in_reach(self.cell, arm, p, self.s.pick_z) < URGENT_SLACK
        tolerance = 0.5 * self.s.grasp_reach / max(self.cell.belt.speed, 1e-9)
        booked = self._committed(other.name, now)
        for _ in range(2):
            plan = planning.schedule(arm, hit.traj, hit.start, other, booked,
                                     self.s.pair_margin, leader=False,
                                     max_delay=self.s.move_timeout)
            if plan is None:
                return hit if urgent else None  # urgent: wait, re-aimed as the belt moves
            if plan.delay <= tolerance:
                return hit
            hit = sorting.intercept(self.cell, arm, self.q[lane.robot], self._aim(item),
                                    hit.start + plan.delay, self.s.pick_z,
                                    lambda q, p: self.plan(lane.robot, q, p))
            if hit is None:
                return None
        return hit if urgent else None

    def _to_bin(self, lane: Lane, now: float) -> None:
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, self.s.drop_clearance)
        self._move_safely(lane, 'to_bin', drop, self._soon(lane, now), now)

    def _move_safely(self, lane: Lane, phase: str, target, start: float, now: float) -> None:
        """Ask for a move like :meth:`_move`; a mirrored pair may go round by a waypoint.

        A pair that would come within the planners' margin goes round, so the follower need
        not yield and both arms start together.
        """
        if len(lane.robots) > 1:
            q0 = self.q[lane.robot]
            try:
                clear = self._pair_clear(lane.robot, self.plan(lane.robot, q0, target))
            except ValueError:
                clear = True  # the planner will refuse it with the reason
            route = [] if clear else self._detour(lane.robot, q0, target)
            if route:
                lane.route = [('via', p) for p in route[1:]] + [(phase, np.asarray(target))]
                self._move(lane, 'via', route[0], start, now)
                return
        self._move(lane, phase, target, start, now)

    def _pair_clear(self, robot: str, traj: Trajectory) -> bool:
        """Return True if ``traj`` and its mirror image (the follower's copy) keep the margin."""
        me, other = self.cell.arm(robot), next(a for a in self.cell.arms if a.name != robot)
        d, _ = collision.trajectory_min_distance(me, traj.t, traj.q, other, traj.t,
                                                 mirror_joints(traj.q))
        return d >= self.s.pair_margin

    def _detour(self, robot: str, q0: np.ndarray, target) -> List[np.ndarray]:
        """Return waypoints (world) whose legs and their mirror images keep the margin.

        Candidates lie out from the belt centre line on the arm's side, at ``VIA_OFFSETS``,
        above the start, the target or half way, at carry height; the first that works wins,
        ``[]`` if none does.
        """
        arm = self.cell.arm(robot)
        start = fk(arm, q0)
        target = np.asarray(target, dtype=float)
        side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
        z = max(start[2], target[2], self.s.carry_z)
        for off in VIA_OFFSETS:
            for x in (start[0], 0.5 * (start[0] + target[0]), target[0]):
                via = np.array([x, self.cell.belt.centre_y + side * off, z])
                try:
                    leg1 = self.plan(robot, q0, via)
                    leg2 = self.plan(robot, leg1.q[-1], target)
                except ValueError:
                    continue
                if self._pair_clear(robot, leg1) and self._pair_clear(robot, leg2):
                    return [via]
        return []

    # --- picking --------------------------------------------------------------------------
    def _pick_next(self, lane: Lane, now: float) -> None:
        arm = self.cell.arm(lane.robot)
        others_busy = any(o.phase != 'idle' for o in self.lanes if o is not lane)
        free = [it for i, it in self.items.items()
                if i not in self.claimed and lane.failures.get(i, 0) < 2]
        if self.s.mode == 'mirrored':  # the leader takes its half; the partner is mirrored
            side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
            free = [it for it in free if np.sign(it.position[1]) == side]
        own = None if self.s.mode == 'single' else True
        order = sorting.order_candidates(self.cell, arm, free, now + self.s.decision_lead,
                                         self.s.pick_z, own, steal=others_busy,
                                         other_cycle=self.s.steal_cycle or None, groups=True)
        if self.s.mode != 'mirrored':
            order = self._cheap_first(lane, order, now)
        for item in [it for _, it in order[:2]]:
            if not self._chase(lane, item, now):
                continue
            self.claimed[item.id] = lane.robot
            if self.s.mode == 'mirrored':
                partner = sorting.mirror_partner(self.cell, item, list(self.items.values()))
                if partner is not None:
                    self.claimed[partner.id] = self.cell.follower.name
            return
        lane.next_look = now + LOOK_AGAIN  # each look plans: not at every tick

    def _cheap_first(self, lane: Lane, order: List[Tuple[int, sorting.SeenItem]],
                     now: float) -> List[Tuple[int, sorting.SeenItem]]:
        """Reorder the first ``CANDIDATES`` of ``order`` (most urgent first): cheap cycles first.

        ``order`` is :func:`scara_collab.core.sorting.order_candidates` with its groups (0:
        the arm's own items and the other half's it must take with them, 1: the other half's
        it takes only after them); groups keep their order. Within them each candidate's cost
        is the bound of the cycle it makes (:func:`scara_collab.core.sorting.cycle_bound`: meet
        it, carry it to its bin): a red item is met upstream near the red bins, a blue one left
        to ride down to the blue bins. Up to ``SAVABLE`` urgent items (less than
        ``URGENT_SLACK`` left in reach) stay in front, most urgent first, so an item the arm can
        still save is not left; more than that means the feed is faster than the arm, and every
        candidate then goes by its cost (the items it cannot save anyway are left, not the ones
        that make its cycles short).
        """
        arm, q0 = self.cell.arm(lane.robot), self.q[lane.robot]
        start, z = now + self.s.decision_lead, self.s.pick_z
        ranked = []
        for k, (group, item) in enumerate(order[:CANDIDATES]):
            p = sorting.predict(self.cell, item, start)
            urgent = sorting.time_in_reach(self.cell, arm, p, z) < URGENT_SLACK
            cost = sorting.cycle_bound(self.cell, arm, q0, item, start, z, self.s.drop_clearance)
            ranked.append([urgent, group, cost, k, (group, item)])
        if sum(e[0] for e in ranked) > SAVABLE:
            for e in ranked:
                e[0] = False  # more urgent items than the arm can save: cost alone
        ranked.sort(key=lambda e: (not e[0], e[3] if e[0] else 0, e[1], e[2], e[3]))
        return [e[4] for e in ranked] + order[CANDIDATES:]

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

    # --- gripper --------------------------------------------------------------------------
    def _grip(self, lane: Lane, grasp: bool, now: float) -> None:
        lane.phase = 'grasping' if grasp else 'releasing'
        lane.since = now
        lane.grips = {}
        for robot in lane.robots:
            self._token += 1
            lane.grips[robot] = GripTrack(self._token, now)
            self._out.append(GripCommand(robot, grasp, self._token))

    def _tick_grip(self, lane: Lane, now: float) -> None:
        grasp = lane.phase == 'grasping'
        for robot, track in lane.grips.items():
            if track.ok is None and now - track.sent > self.s.grip_timeout:
                if track.attempts > self.s.grip_retries:
                    track.ok, track.message = False, f'no answer after {track.attempts} calls'
                    continue
                self._token += 1
                track.token, track.sent = self._token, now
                track.attempts += 1
                self.retries += 1
                self.log('info', f'{robot}: no gripper answer in {self.s.grip_timeout:g} s; '
                         f'asking again ({track.attempts})')
                self._out.append(GripCommand(robot, grasp, track.token))
        if any(t.ok is None for t in lane.grips.values()):
            return
        main = lane.grips[lane.robot]
        for robot, track in lane.grips.items():
            if robot != lane.robot and not track.ok:
                self.log('warn', f'{robot} gripper: {track.message}')
        if not grasp:
            if lane.item is not None:
                self.claimed.pop(lane.item.id, None)
            if not main.ok:
                self.log('warn', f'{lane.robot}: release failed ({main.message})')
            self._idle(lane)
        elif not main.ok:
            item = lane.item
            lane.failures[item.id] = lane.failures.get(item.id, 0) + 1
            self.claimed.pop(item.id, None)
            self.log('info', f'{lane.robot}: grasp of item {item.id} failed ({main.message})')
            self._idle(lane)
        elif self.s.carry_z > self.s.pick_z + 1e-6 and self._would_sweep(lane, now):
            up = np.array([lane.target[0], lane.target[1], self.s.carry_z])
            lane.bin_tries, lane.holding = 0, True
            self._move(lane, 'lift', up, self._soon(lane, now), now)
        else:
            lane.bin_tries, lane.holding = 0, True
            self._to_bin(lane, now)

    def _would_sweep(self, lane: Lane, now: float) -> bool:
        """Return True if the item just grasped would touch an item on the belt on its way.

        Then it is lifted clear first. A held item hangs with its bottom ``pick_z - belt
        top`` below the tool; the move to the bin (as the planner will plan it) is checked
        against every other item's predicted position, with ``carry_clearance`` to spare
        (in mirrored mode the follower's mirror
        image too). Checking costs about a millisecond; lifting costs a move.
        """
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, self.s.drop_clearance)
        try:
            traj = self.plan(lane.robot, self.q[lane.robot], drop)
        except ValueError:
            return True
        others = [it for it in self.items.values() if it.id != lane.item.id]
        if not others:
            return False
        belt, size = self.cell.belt, self.cell.item_size
        spare = self.s.carry_z - self.s.pick_z - size  # = carry_clearance
        low = traj.p[:, 2] - self.s.pick_z < size + spare  # held bottom below item tops
        if not np.any(low):
            return False
        t = self._soon(lane, now) + traj.t[low]
        path = traj.p[low, :2]
        paths = [path] + ([path * [1.0, -1.0] + [0.0, 2 * belt.centre_y]]
                          if len(lane.robots) > 1 else [])
        for it in others:
            x = it.position[0] + belt.speed * (t - it.stamp)
            for p in paths:
                if np.any((np.abs(p[:, 0] - x) < size + spare)
                          & (np.abs(p[:, 1] - it.position[1]) < size + spare)):
                    return True
        return False

    # --- endings --------------------------------------------------------------------------
    def _idle(self, lane: Lane) -> None:
        lane.phase, lane.item, lane.moves, lane.grips = 'idle', None, {}, {}
        lane.holding, lane.route = False, []
        lane.reaims = 0

    def _give_up(self, lane: Lane, now: float, why: str) -> None:
        self.log('warn', f'{lane.robot}: {why}')
        self.give_ups += 1
        self.last_give_up = f't={now:.2f} s {lane.robot} {lane.phase}: {why}'
        phase = lane.phase
        lane.route = []
        if lane.holding and phase in MOVING:  # never put an item down off the bin
            lane.bin_tries += 1
            if lane.bin_tries <= self.s.bin_retries:
                self._to_bin(lane, now)
                return
            self.log('warn', f'{lane.robot}: releasing item {lane.item.id} where it is after '
                     f'{lane.bin_tries} bin moves')
            self._grip(lane, False, now)
            return
        if lane.item is not None:
            self.claimed.pop(lane.item.id, None)
            lane.failures[lane.item.id] = lane.failures.get(lane.item.id, 0) + 1
        self._idle(lane)
        if phase == 'to_park':  # the park move itself failed: stay idle, do not loop
            return
        self._park(lane, now)

    def _park(self, lane: Lane, now: float) -> None:
        """Wait clear of the shared zone, above the first bin, so the other arm is free."""
        park = sorting.drop_point(self.cell, lane.robot, self.cell.item_classes[0],
                                  self.s.drop_clearance)
        self._move_safely(lane, 'to_park', park, self._soon(lane, now), now)

    # --- figures --------------------------------------------------------------------------
    def minutes(self, now: float) -> float:
        """Minutes since the job started (0 before)."""
        return 0.0 if self.start_time is None else max(0.0, now - self.start_time) / 60.0

    def rate(self, now: float) -> float:
        """Items sorted per minute since the job started (:func:`items_per_minute`)."""
        return items_per_minute(self.counts.get('sorted', 0), self.minutes(now) * 60.0)
