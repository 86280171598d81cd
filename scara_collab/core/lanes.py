"""The job's lanes and their request protocol, without ROS: asked, answered, retried, timed out.

A *lane* is one arm's work (both arms' in mirrored mode): a :class:`Lane` holds what it is
doing now, in one of the :class:`Phase` phases. :class:`LaneProtocol` keeps what is known of
each lane's current move (per arm: the planner's and the bridge's answers, its start and end,
whether it arrived), opens the job's move requests and enforces every move deadline;
:class:`Grips` does the same for the grippers (tokens, retries, measured answer times). Both
decide nothing about items: asked for a move or a grip they return the command to send;
advanced to ``now`` they return the commands sent again and the :class:`LaneEvent` that ends
the lane's wait (``arrived``, ``gripped`` or ``failed``), which the job decides on.

Neither keeps the lanes: the job owns them and passes those an answer may be about.

Every observation names what it is about (a move by its request, a grip by its token), so a
late, duplicated or unknown one is ignored. Move requests are identified by their requested
start in integer nanoseconds (:mod:`scara_collab.nodes.protocol` carries that id through
planner and bridge); they are unique per arm.
"""
from dataclasses import dataclass, field
from enum import Enum
import textwrap
from typing import Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from scara_collab.core import sorting
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_point
from scara_collab.core.model import CellModel
from scara_collab.core.move_time import Lateness, MoveTime
from scara_collab.core.moves import PLANNER_STATES
from scara_collab.core.trajectory import Trajectory


class Phase(str, Enum):
    """A lane's phase: what it waits for, and the deadline of that wait.

    Each member's value is its name in statuses and logs (``'to_item'``); :attr:`leaves` and
    :attr:`deadline` are the job's table of phases (:func:`phase_table`), so the table and the
    phases cannot part.
    """

    IDLE = ('idle', 'an item can be met: a pick move is asked', 'none')
    TO_ITEM = ('to_item', "every arm's move has arrived (the bridge's ``finished``, the end "
               'of the move it accepted, or the end time passed with the tool at the target): '
               'grasp if the item is under the tool, else chase it or give up',
               'no planner answer in ``answer_timeout``: asked again ``answer_retries`` '
               'times; not planned by ``move_timeout``; not arrived ``arrive_timeout`` after '
               'its end (give up, park)')
    GRASPING = ('grasping', "every gripper answered (or the bridge's ``grasped`` event "
                'confirmed it)', '``grip_timeout``: called again ``grip_retries`` times '
                '(give up)')
    LIFT = ('lift', 'as ``to_item``; only when the item, carried straight to its bin, would '
            'touch one still on the belt (``lift_after_grasp``)', 'as ``to_item``')
    VIA = ('via', 'as ``to_item``: a waypoint of a detour (a mirrored pair kept apart, an '
           "arm backing out of the other's way), then the next leg", 'as ``to_item``')
    TO_BIN = ('to_bin', 'as ``to_item``', 'as ``to_item`` with ``carry_timeout``; a given up '
              'bin move is asked again')
    RELEASING = ('releasing', 'every gripper answered (or ``released`` seen)', 'as '
                 '``grasping``')
    TO_PARK = ('to_park', 'as ``to_item``', 'as ``to_item`` (then idle)')

    def __new__(cls, value: str, leaves: str = '', deadline: str = ''):
        """Make the member ``value`` with its table row."""
        member = str.__new__(cls, value)
        member._value_ = value
        member.leaves, member.deadline = leaves, deadline
        return member

    def __str__(self) -> str:
        """Return the phase's name (``'to_item'``)."""
        return self.value

    def __format__(self, spec: str) -> str:
        """Format as the phase's name."""
        return format(self.value, spec)


#: the phases that wait for a move
MOVING = frozenset({Phase.TO_ITEM, Phase.LIFT, Phase.VIA, Phase.TO_BIN, Phase.TO_PARK})


def phase_table(width: int = 92) -> str:
    """Return the phases as a reStructuredText table: phase, leaves when, deadline (then).

    >>> phase_table().splitlines()[2].split()[:2]
    ['phase', 'leaves']
    """
    cols = (14, (width - 14) // 2, width - 14 - (width - 14) // 2)
    rows = [('phase', 'leaves when', 'deadline (then)')] + [
        (f'``{p.value}``', p.leaves, p.deadline) for p in Phase]
    rule = '  '.join('=' * (c - 1) for c in cols)
    out = ['', rule]
    for k, row in enumerate(rows):
        cells = [textwrap.wrap(text, c - 1) or [''] for text, c in zip(row, cols)]
        for line in range(max(len(c) for c in cells)):
            out.append('  '.join((c[line] if line < len(c) else '').ljust(w - 1)
                                 for c, w in zip(cells, cols)).rstrip())
        if k == 0:
            out.append(rule)
    out.append(rule)
    return '\n'.join(out)


#: planner / bridge answers about a move, in the order a move goes through them
MOVE_STATES = ('asked', 'queued', 'waiting', 'planned', 'accepted', 'finished')
#: s: an accepted move's end as a status carries it (rounded) may be this far off the bridge's
END_SLACK = 1e-6
FAILED_MOVE = ('refused', 'superseded', 'held')
#: what ends a lane's wait (:class:`LaneEvent`)
EVENTS = ('arrived', 'gripped', 'failed')
#: s: the most a grasp is aimed ahead of the tool's arrival (the gripper's reach is 0.06 m,
#: 0.3 s of belt travel either way: aiming further than that misses for certain)
GRASP_LEAD = 0.25
#: the state a planner's status puts a move in (a state not listed changes nothing)
PLANNER_STATUS = {s: s for s in PLANNER_STATES}
#: the same for the bridge's; ``preempted`` by the arm's own planner (its new move, its hold): the
#: planner took it back and says what comes next (a take-over by anyone else comes as refused)
BRIDGE_STATUS = {'accepted': 'accepted', 'finished': 'finished', 'preempted': 'waiting',
                 'refused': 'refused', 'held': 'held'}

PlanFn = Callable[[str, np.ndarray, np.ndarray], Trajectory]


@dataclass(frozen=True)
class MoveCommand:
    """Ask the planner(s) for a move: ``robot``'s tool to ``target`` (world), from ``start``.

    ``mirrored``: send it to the replication manager (``/collab/target``), which moves the
    follower to the mirror image with the same request. ``request`` (ns) is the target's
    stamp and the move's identity; a re-sent request has the same one. ``plan``: the job's
    own plan of ``robot``'s move (from the arm's state when asked, ending at ``target``),
    offered to the planner (a mirrored pair's: through the replication manager, which mirrors
    it for the follower) so it is not planned twice; None if the job cannot plan it (the
    planner then plans the target, or refuses it with the reason).
    """

    robot: str
    target: np.ndarray
    request: int
    mirrored: bool
    purpose: str
    plan: Optional[Trajectory] = None

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


#: what the job sends: a move or a gripper call
Command = Union[MoveCommand, GripCommand]


@dataclass
class MoveTrack:
    """What is known of one arm's move of the current request."""

    state: str = 'asked'
    since: float = 0.0  # when it entered this state (for 'waiting')
    start: Optional[float] = None
    end: Optional[float] = None
    reason: str = ''
    arrived: bool = False


@dataclass
class GripTrack:
    """One gripper request: its token, when it was sent, how often, its outcome.

    ``calls``: every attempt's token and when it was sent. The gripper is idempotent, so the
    answer to any attempt is the answer (a slow one is not lost by asking again).
    """

    token: int
    sent: float
    attempts: int = 1
    ok: Optional[bool] = None
    message: str = ''
    calls: Dict[int, float] = field(default_factory=dict)


@dataclass
class Lane:
    """One arm's work (both arms' in mirrored mode); see :mod:`scara_collab.core.job`.

    ``robot`` is the arm the lane decides for; ``robots`` every arm it moves (``robot`` first).
    """

    robot: str
    robots: Tuple[str, ...]
    phase: Phase = Phase.IDLE
    item: Optional[sorting.SeenItem] = None
    target: Optional[np.ndarray] = None
    request: int = 0
    purpose: str = ''
    plan: Optional[Trajectory] = None  # the job's plan of the current move (lane.robot's)
    since: float = 0.0
    sent: float = 0.0
    sends: int = 0
    moves: Dict[str, MoveTrack] = field(default_factory=dict)
    grips: Dict[str, GripTrack] = field(default_factory=dict)
    bin_tries: int = 0
    reaims: int = 0
    holding: bool = False
    route: List[Tuple[Phase, np.ndarray]] = field(default_factory=list)
    failures: Dict[int, int] = field(default_factory=dict)
    next_look: float = 0.0  # idle with nothing to take: look again from then

    @property
    def mirrored(self) -> bool:
        """Return True if the lane moves a mirrored pair (the follower to the mirror image)."""
        return len(self.robots) > 1

    def idle(self) -> None:
        """Forget the current item, move and grips: the lane is free for the next item."""
        self.phase, self.item, self.moves, self.grips = Phase.IDLE, None, {}, {}
        self.holding, self.route, self.reaims = False, [], 0


@dataclass(frozen=True, eq=False)
class LaneEvent:
    """What ended a lane's wait: ``kind`` one of :data:`EVENTS`; ``why`` a failure's reason.

    ``arrived``: every arm of ``lane`` completed its move; ``gripped``: every gripper of it
    answered (or was given up: its :class:`GripTrack` says ``ok`` False); ``failed``: a move
    was refused or ran out of time. ``waited``: for a move never planned, the state it waited
    in (the reason then also names what the other lanes were doing when it was decided).
    """

    kind: str
    lane: Lane
    why: str = ''
    waited: str = ''


class PlanMemo:
    """A plan function (:data:`PlanFn`) that plans each move once until :meth:`forget`.

    A decision and the move it then asks for plan the same move in the same tick (the check
    that a carried item clears the belt, then the move to the bin): the second gets the
    first's trajectory. The job forgets at every tick (the arms have moved on).

    :param plan: ``plan(robot, q_start, target) -> Trajectory`` (raises ``ValueError`` if
        refused).
    """

    def __init__(self, plan: PlanFn):
        """Wrap ``plan``; nothing planned yet."""
        self._plan = plan
        self._plans: Dict[tuple, object] = {}  # trajectories (or refusals) by their inputs

    def __call__(self, robot: str, q_start, target) -> Trajectory:
        """Return the plan of the move, planned now or earlier since the last :meth:`forget`.

        :raises ValueError: the move is refused (the same reason each time).
        """
        key = (robot, np.asarray(q_start, dtype=float).tobytes(),
               np.asarray(target, dtype=float).tobytes())
        found = self._plans.get(key)
        if found is None:
            try:
                found = self._plan(robot, q_start, target)
            except ValueError as exc:
                found = str(exc)
            self._plans[key] = found
        if isinstance(found, str):
            raise ValueError(found)
        return found

    def forget(self) -> None:
        """Forget every plan."""
        self._plans.clear()


class LaneProtocol:
    """The lanes' move requests, asked and tracked to an outcome (see the module docstring).

    :param cell: the cell model.
    :param settings: the timeouts, retries and the start rule's leads.
    :param plan: ``plan(robot, q_start, target) -> Trajectory`` with the planners' settings
        (raises ``ValueError`` if refused): the plan a move is offered with.
    :param log: ``log(level, text)`` for events worth a log line (``'info'``, ``'warn'``).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn,
                 log: Callable[[str, str], None] = lambda level, text: None):
        """Nothing is asked yet."""
        self.cell, self.settings, self.log = cell, settings, log
        self.plan = plan
        #: the arms' measured joints ``(3,)`` by name
        self.q: Dict[str, np.ndarray] = {}
        #: move requests sent again so far
        self.move_retries = 0
        #: sim s of the latest tick (answers are timed against it)
        self.now = 0.0
        self._last_request: Dict[str, int] = {a.name: 0 for a in cell.arms}
        # how long answers have lately taken (sim s): added to the timeouts, so a slow graph
        # (real time, a busy machine) is waited for as it measures, not as lockstep would be
        self.answer_lag = Lateness()
        #: the lanes' gripper calls
        self.grips = Grips(settings, log)
        #: the start rule, with how late the bridge started the job's moves (sim s)
        self.time = MoveTime(settings.leads)
        #: s: each arm's trajectory clock behind sim time (speed scaling): the times its
        #: moves' requests and statuses carry are its trajectory time
        self.lags: Dict[str, float] = {}

    @property
    def retries(self) -> int:
        """Requests and gripper calls sent again so far."""
        return self.move_retries + self.grips.retries

    def knows_every_arm(self) -> bool:
        """Return True once every arm's joints have been measured."""
        return len(self.q) >= len(self.cell.arms)

    # --- observations -----------------------------------------------------------------------
    def measured(self, robot: str, q: np.ndarray) -> None:
        """Take the measured joints of ``robot`` ``(3,)`` (finite, checked by the caller)."""
        self.q[robot] = np.asarray(q, dtype=float)

    def on_planner(self, lanes: Sequence[Lane], robot: str, request: int, state: str,
                   start: Optional[float], end: Optional[float],
                   reason: str = '') -> Optional[MoveTrack]:
        """Take a planner status about ``robot``'s move for ``request`` (others are ignored).

        :param lanes: the job's lanes (the status is about one of their moves, or none).
        :return: the move's track if the status changed it, else None.
        """
        for lane in lanes:  # the first answer to a request: how long answers take
            track = lane.moves.get(robot) if lane.request == request else None
            if track is not None and track.state == 'asked' and lane.phase in MOVING:
                self.answer_lag.add(self.now - lane.sent)
        return self._on_status(lanes, robot, request, PLANNER_STATUS.get(state), start, end,
                               reason)

    def on_execution(self, lanes: Sequence[Lane], robot: str, request: int, state: str,
                     start: Optional[float], end: Optional[float], reason: str = '',
                     stamp: Optional[float] = None) -> Optional[MoveTrack]:
        """Take a bridge execution status about ``robot``'s move for ``request``.

        :param stamp: the start it asked for (``accepted``; None or 0: none): how late it
            started is measured into the start rule (:attr:`time`).
        :return: the move's track if the status changed it, else None.
        """
        if state == 'accepted' and stamp and open_track(lanes, robot, request) is not None:
            self.time.started(stamp, start)
        return self._on_status(lanes, robot, request, BRIDGE_STATUS.get(state), start, end,
                               reason)

    def _on_status(self, lanes: Sequence[Lane], robot: str, request: int, new: Optional[str],
                   start: Optional[float], end: Optional[float],
                   reason: str) -> Optional[MoveTrack]:
        """Move the track of ``robot``'s move ``request`` to the state ``new``."""
        track = open_track(lanes, robot, request)
        if track is None or new is None:
            return None
        if new in ('planned', 'accepted'):
            if new == 'planned' and track.state == 'accepted' and abs(start - track.start) < 1e-6:
                return None  # the bridge already runs it (its start is the one that counts)
            track.state, track.start, track.end = new, start, end
        elif new in ('queued', 'waiting'):  # not (or no longer) committed
            if track.state != new:
                track.since = self.now
            track.state, track.start, track.end = new, None, None
        elif new == 'finished':
            track.state = new
        else:
            track.state, track.reason = new, reason or new
        return track

    # --- moves --------------------------------------------------------------------------------
    def _request(self, robots: Sequence[str], start: float) -> int:
        req = max([int(round(start * 1e9))] + [self._last_request[r] + 1 for r in robots])
        for r in robots:
            self._last_request[r] = req
        return req

    def open(self, lane: Lane, phase: Phase, target, start: float, now: float,
             traj: Optional[Trajectory] = None) -> MoveCommand:
        """Open ``lane``'s request of a move to ``target`` from ``start``; return its command.

        The lane enters ``phase`` with a new request (its start by the start rule,
        :meth:`~scara_collab.core.move_time.MoveTime.requested`). The move goes with the job's
        plan of it (``traj``, else planned here from the arm's state; a mirrored pair's: the
        lane's arm), which the planner takes instead of planning it again.
        """
        lane.phase, lane.target = Phase(phase), np.asarray(target, dtype=float)
        lag = self.lags.get(lane.robot, 0.0)
        lane.request = self._request(lane.robots, self.time.requested(start - lag, now - lag))
        lane.moves = {r: MoveTrack() for r in lane.robots}
        lane.since = lane.sent = now
        lane.sends = 1
        lane.plan = None
        if lane.robot in self.q:
            try:
                lane.plan = traj or self.plan(lane.robot, self.q[lane.robot], lane.target)
            except ValueError:
                pass  # the planner will refuse it with the reason
        return self._command(lane)

    def open_once(self, robot: str, target, start: float, purpose: str) -> MoveCommand:
        """Return a move of ``robot`` that no lane follows up (an unused arm's park)."""
        return MoveCommand(robot, np.asarray(target, dtype=float),
                           self._request([robot], start - self.lags.get(robot, 0.0)), False,
                           purpose)

    def _command(self, lane: Lane) -> MoveCommand:
        return MoveCommand(lane.robot, lane.target, lane.request, lane.mirrored,
                           str(lane.phase), lane.plan)

    def target_of(self, lane: Lane, robot: str) -> np.ndarray:
        """Return where ``lane``'s current move takes ``robot``'s tool (world)."""
        if robot == lane.robot:
            return lane.target
        return mirror_point(self.cell.arm(lane.robot), self.cell.arm(robot), lane.target)

    def _at_target(self, lane: Lane, robot: str) -> bool:
        q = self.q.get(robot)
        if q is None:
            return False
        tip = fk(self.cell.arm(robot), q)
        return float(np.linalg.norm(tip - self.target_of(lane, robot))) <= \
            self.settings.arrive_tolerance

    # --- the clock ----------------------------------------------------------------------------
    def advance(self, lane: Lane, now: float) -> Tuple[List[Command], Optional[LaneEvent]]:
        """Follow ``lane``'s move or grip to ``now`` (sim s).

        :return: the commands sent again (a lost answer), in order, and the event that ends
            the lane's wait, or None while it waits (always None for an idle lane).
        """
        if lane.phase in MOVING:
            return self._follow_move(lane, now)
        if lane.phase in (Phase.GRASPING, Phase.RELEASING):
            return self.grips.follow(lane, now)
        return [], None

    def _follow_move(self, lane: Lane, now: float) -> Tuple[List[Command], Optional[LaneEvent]]:
        s = self.settings
        out: List[Command] = []
        limit = s.carry_timeout if lane.holding else s.move_timeout
        for robot, track in lane.moves.items():
            if track.arrived:
                continue
            at = now - self.lags.get(robot, 0.0)  # the arm's trajectory time: its moves'
            if track.state in FAILED_MOVE:
                return out, LaneEvent('failed', lane,
                                      f'{robot} move {track.state}: {track.reason}')
            if track.state == 'finished' or (track.state == 'accepted'
                                             and at >= track.end - END_SLACK):
                # the bridge says finished at the first instant at or after the end of a move
                # it accepted: decided at that instant, not when its word comes in (a tick
                # later or not, by how the messages were delivered)
                track.arrived = True
                continue
            if (track.state == 'asked'
                    and now - lane.sent > s.answer_timeout + self.answer_lag.worst):
                if lane.sends > s.answer_retries:
                    return out, LaneEvent('failed', lane, f'no answer from the {robot} planner '
                                          f'after {lane.sends} requests')
                lane.sends += 1
                lane.sent = now
                self.move_retries += 1
                self.log('info', f'{robot}: no planner answer for request {lane.request} in '
                         f'{s.answer_timeout:g} s; asking again ({lane.sends})')
                out.append(self._command(lane))
                continue
            if track.end is None:  # asked, queued or waiting
                if now - lane.since > limit:
                    return out, LaneEvent('failed', lane, f'no plan from the {robot} planner in '
                                          f'{limit:g} s', waited=track.state)
                continue
            if at >= track.end and self._at_target(lane, robot):
                track.arrived = True
            elif at > track.end + s.arrive_timeout:
                return out, LaneEvent('failed', lane, f'{robot} did not arrive within '
                                      f'{s.arrive_timeout:g} s of its end ({track.state})')
        if all(t.arrived for t in lane.moves.values()):
            return out, LaneEvent('arrived', lane)
        return out, None


def open_track(lanes: Sequence[Lane], robot: str, request: int) -> Optional[MoveTrack]:
    """Return the track of ``robot``'s current move ``request``, None if unknown or over."""
    for lane in lanes:
        if lane.phase in MOVING and lane.request == request and robot in lane.moves:
            track = lane.moves[robot]
            return None if track.state in ('finished',) + FAILED_MOVE else track
    return None


class Grips:
    """The lanes' gripper calls: asked, answered (by a response or a bridge event), retried."""

    def __init__(self, settings: JobSettings, log: Callable[[str, str], None]):
        """No call made yet."""
        self.settings, self.log = settings, log
        #: how long gripper answers have lately taken, sim s (added to the timeout)
        self.lag = Lateness()
        #: gripper calls made again so far
        self.retries = 0
        self._token = 0

    @property
    def lead(self) -> float:
        """Return how long after the tool's arrival a grasp takes hold, as measured, s.

        The typical gripper answer time (a round trip: seeing the arrival, then the call), at
        most ``GRASP_LEAD``; 0 in lockstep, where the call is answered within the tick.
        """
        return min(self.lag.typical, GRASP_LEAD)

    def ask(self, lane: Lane, grasp: bool, now: float) -> List[GripCommand]:
        """Call every gripper of ``lane`` (``grasp`` or release); return the calls to make."""
        lane.phase = Phase.GRASPING if grasp else Phase.RELEASING
        lane.since = now
        lane.grips = {}
        out = []
        for robot in lane.robots:
            self._token += 1
            lane.grips[robot] = GripTrack(self._token, now, calls={self._token: now})
            out.append(GripCommand(robot, grasp, self._token))
        return out

    def on_response(self, lanes: Sequence[Lane], token: int, ok: bool, message: str,
                    now: float) -> None:
        """Take a gripper response for request ``token``: any attempt of a grip still open."""
        for lane in lanes:
            for track in lane.grips.values():
                if track.ok is None and (token == track.token or token in track.calls):
                    track.ok, track.message = bool(ok), message
                    self.lag.add(now - track.calls.get(token, track.sent))

    def confirm(self, lanes: Sequence[Lane], kind: str, robot: str) -> None:
        """Take a bridge item event: ``grasped`` or ``released`` answers a lost response."""
        phase = {'grasped': Phase.GRASPING, 'released': Phase.RELEASING}.get(kind)
        for lane in lanes:
            track = lane.grips.get(robot)
            if lane.phase == phase and track is not None and track.ok is None:
                track.ok, track.message = True, f'{kind} event'

    def follow(self, lane: Lane, now: float) -> Tuple[List[Command], Optional[LaneEvent]]:
        """Call again the grippers of ``lane`` that did not answer in time; see the event."""
        s = self.settings
        out: List[Command] = []
        grasp = lane.phase == Phase.GRASPING
        for robot, track in lane.grips.items():
            if track.ok is None and now - track.sent > s.grip_timeout + self.lag.worst:
                if track.attempts > s.grip_retries:
                    track.ok, track.message = False, f'no answer after {track.attempts} calls'
                    continue
                self._token += 1
                track.token, track.sent = self._token, now
                track.calls[self._token] = now
                track.attempts += 1
                self.retries += 1
                self.log('info', f'{robot}: no gripper answer in {s.grip_timeout:g} s; '
                         f'asking again ({track.attempts})')
                out.append(GripCommand(robot, grasp, track.token))
        if all(t.ok is not None for t in lane.grips.values()):
            return out, LaneEvent('gripped', lane)
        return out, None
