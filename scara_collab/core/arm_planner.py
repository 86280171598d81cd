"""One arm's planner as a state machine, without ROS: observations in, commands out.

:class:`ArmPlanner` decides everything a planner node does; the node only turns messages into
the ``on_*`` observations and the returned :class:`SendMove`, :class:`HoldArm` and
:class:`Status` commands into messages.

**Requests.** A move is asked for as a target point (:meth:`ArmPlanner.on_target`) or as a
plan of it (:meth:`ArmPlanner.on_offer`: the sorting job offers the trajectory it planned
with the planners' settings, :func:`scara_collab.core.planning.offered_move`). Each is named
by its request: the stamp in ns, or for a target stamped zero its receipt time
(:meth:`Answers.request_of`). A request already answered is not planned again: its last status
is sent again (:class:`Answers`).

**Planning.** The move is planned from the arm's measured joints (a straight line, a joint
move, or either, setting ``mode``); an offered plan that starts where the arm is (within
``offer_tolerance``) is taken as is when the mode is ``line_or_joint`` (the job's). When it
starts is the start rule's (:class:`scara_collab.core.move_time.MoveTime`): at the requested
time if it can still be sent in time, a move asked for now after the planning lead, else as
soon as it can be sent, each lead grown by the worst lateness the bridge measured on this
arm's recent starts. It is scheduled against the other arm's
committed motion (:class:`scara_collab.core.motion.Heard`, kept from the other arm's
trajectories and the bridge's statuses of them) by the priority rule of
:mod:`scara_collab.core.planning`, applied here, once.

**Statuses** (:data:`STATES`): ``planned`` (the move is sent; also again when it is re-timed),
``queued`` (behind the arm's running move: the bridge replaces a running trajectory, so it
is sent when that move ends), ``waiting`` (the other arm's committed motion blocks it even
after ``max_delay``: retried whenever that arm commits a new move, refused after
``max_wait``), ``superseded`` (a queued or waiting request replaced by a newer one),
``refused`` (with the reason; the arm stays where it is). A request that comes while the
arm's sent move has surely not begun (its start further off than the worst start lateness
measured) supersedes that one too: the arm is held where it is, which drops the move at the
bridge, and the new request is planned from there.

**Follower re-timing.** The follower's committed move that has not started yet (its start
is further off than the worst start lateness measured) is scheduled again when a new leader
move is heard: delayed if it would now conflict, or, if no delay helps, the arm is held
(:class:`HoldArm`) and the move waits. If the bridge refuses the re-timed move (the first
one had started after all: it would not begin where the arm is), the first one stays the
arm's commitment. Either way the bridge judges every waiting move again as it takes over.

**Start lateness.** When the bridge reports the arm's move started late, the move is re-based
to its real start (its ``planned`` status is sent again with the new window) and the
lateness is measured into the start rule (:meth:`scara_collab.core.move_time.MoveTime.started`).

All times are absolute sim seconds from the ``clock`` given to :class:`ArmPlanner`.
"""
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Callable, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core.config import Rule
from scara_collab.core.kinematics import fk, IKError
from scara_collab.core.model import ArmModel
from scara_collab.core.motion import Heard, schedule_for_door
from scara_collab.core.move_time import lateness, Leads, MoveTime
from scara_collab.core.moves import PLANNER_STATES
from scara_collab.core.planning import (MODES, offered_move, path_options, Plan, plan_path,
                                        schedule, starts_at, Timeline)
from scara_collab.core.trajectory import path_metrics, Trajectory

#: the states of a request a planner reports (:data:`scara_collab.core.moves.PLANNER_STATES`)
STATES = PLANNER_STATES

#: the planner's times, s, parameters of its node that may change while it runs: the send
#: margin of the start rule (:class:`scara_collab.core.move_time.Leads`; ``--lockstep off`` sets
#: ``graph.REALTIME_SEND_MARGIN``), the most a move waits for the other arm (``max_delay``),
#: and how long a blocked move waits before it is refused (``max_wait``)
TIMES = {'send_margin': 0.05, 'max_delay': 30.0, 'max_wait': 60.0}


def planner_parameters(robot: str, robots: Sequence[str]) -> Tuple[Dict[str, object],
                                                                   Tuple[Rule, ...]]:
    """Return a planner node's parameters (defaults) and the rules they must meet.

    ``robot`` (the default arm) must be one of ``robots``, ``mode`` one of :data:`MODES`,
    every time of :data:`TIMES` > 0; ``profile`` names the arm profile ('' the cell's).

    >>> defaults, rules = planner_parameters('scara_left', ['scara_left', 'scara_right'])
    >>> sorted(defaults), [r.key for r in rules if r.kind == 'positive']
    (['max_delay', 'max_wait', 'mode', 'profile', 'robot', 'send_margin'], \
['send_margin', 'max_delay', 'max_wait'])
    """
    return ({'robot': robot, 'profile': '', 'mode': 'line_or_joint', **TIMES},
            (Rule('robot', 'str', lambda v: v in robots, f'must be one of {list(robots)}'),
             Rule('profile', 'text'),
             Rule('mode', 'str', lambda v: v in MODES, f'must be one of {MODES}'),
             *(Rule(key, 'positive') for key in TIMES)))


#: requests whose last status is kept, to answer a re-sent one
HISTORY = 64
#: m: a planned move whose tool leaves the straight line by less than this is a ``line``
LINE_DEVIATION = 1e-4
#: the execution states after which nothing of the arm's own move runs any more
NOT_RUNNING = ('refused', 'preempted', 'held')


@dataclass(frozen=True)
class PlannerSettings:
    """How an arm's planner plans and schedules (its parameters and the cell's margin).

    :ivar mode: one of :data:`scara_collab.core.planning.MODES`.
    :ivar leads: the start rule's leads (``planning``, ``send``:
        :class:`scara_collab.core.move_time.Leads`).
    :ivar max_delay: s, the most a move is delayed for the other arm's committed motion.
    :ivar max_wait: s, how long a move blocked by the other arm waits before it is refused.
    :ivar margin: m between the arms' capsules that a move keeps (the cell's safety margin
        plus the planning buffer).
    :ivar trajectory: ``controllers.yaml`` ``trajectory`` (sample period, DLS,
        ``offer_tolerance``).
    """

    mode: str
    leads: Leads
    max_delay: float
    max_wait: float
    margin: float
    trajectory: dict

    @classmethod
    def of(cls, params: Mapping[str, object], safety_margin: float,
           controllers: Mapping[str, object]) -> 'PlannerSettings':
        """Return the settings of a planner node's parameters (``mode``, :data:`TIMES`).

        :param safety_margin: the cell's, m (``planning_buffer`` is added to it).
        :param controllers: ``controllers.yaml`` (``planning_lead``, ``planning_buffer``,
            ``trajectory``).
        """
        return cls(str(params['mode']), Leads.of(controllers=controllers,
                                                 send_margin=params['send_margin']),
                   margin=safety_margin + float(controllers['planning_buffer']),
                   trajectory=controllers['trajectory'], max_delay=float(params['max_delay']),
                   max_wait=float(params['max_wait']))

    def __post_init__(self):
        """Refuse a mode not in :data:`~scara_collab.core.planning.MODES` or a time <= 0."""
        if self.mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {self.mode!r}')
        for key in ('max_delay', 'max_wait'):
            if not float(getattr(self, key)) > 0.0:
                raise ValueError(f'{key} must be > 0, got {getattr(self, key)!r}')


class MoveRequest(NamedTuple):
    """A move asked for: where to, in which frame, the plan offered with it, and its request.

    :ivar target: ``(3,)`` the tool's goal, m.
    :ivar frame: ``'world'`` or ``'base'`` (the arm's base).
    :ivar wanted: s: the requested start while queued (0 = as soon as possible); once planned
        or waiting, when it was first wanted (so a wait counts into its delay).
    :ivar offer: the plan offered with it, or None.
    :ivar request: its request id, ns.
    """

    target: np.ndarray
    frame: str
    wanted: float
    offer: Optional[Trajectory]
    request: int


class CommittedMove(NamedTuple):
    """The arm's own move as sent: its plan (start, delay) and the request it answers.

    :ivar retimed: the plan this one re-times, until the bridge accepts the new one (if it
        refuses it, the move it re-timed is what the arm is committed to); None otherwise.
    :ivar begun: the bridge is known to have begun it (it refused its re-time), whatever its
        planned start says.
    """

    plan: Plan
    asked: MoveRequest
    retimed: Optional[Plan] = None
    begun: bool = False

    @property
    def request(self) -> int:
        """The request id, ns."""
        return self.asked.request


@dataclass(frozen=True)
class Status:
    """Report ``state`` of ``request`` (:data:`STATES`); ``repeated``: an answer sent again.

    ``start``, ``end`` and ``delay`` (s) describe a planned move; ``kind`` is ``line`` or
    ``joint move``.
    """

    state: str
    request: int
    reason: str = ''
    start: Optional[float] = None
    end: Optional[float] = None
    delay: float = 0.0
    kind: str = ''
    repeated: bool = False


@dataclass(frozen=True)
class SendMove:
    """Send the arm's move for ``request``: ``plan.traj`` stamped ``plan.start``, and its path."""

    request: int
    plan: Plan


@dataclass(frozen=True)
class HoldArm:
    """Send a hold: the arm keeps ``q`` (``(3,)``), dropping its move that has not started."""

    q: np.ndarray


PlannerCommand = Union[Status, SendMove, HoldArm]


class Answers:
    """The last status of each request, so a re-sent one is answered, not planned again.

    Keeps the last :data:`HISTORY` requests; a target stamped zero gets its receipt time as
    its request id (:meth:`request_of`), unique even for two in the same nanosecond.

    >>> answers = Answers()
    >>> answers.request_of(0, 1000), answers.request_of(0, 1000), answers.request_of(7, 1000)
    (1000, 1001, 7)
    >>> answers.keep(Status('queued', 7)); answers.last(7).state, answers.last(8)
    ('queued', None)
    """

    def __init__(self, history: int = HISTORY):
        """Remember nothing yet."""
        self.history = int(history)
        self._last: 'OrderedDict[int, Status]' = OrderedDict()
        self._last_receipt = 0

    def request_of(self, stamp_ns: int, now_ns: int) -> int:
        """Return the request id of a target: its stamp, or (stamped zero) the receipt time."""
        if stamp_ns:
            return stamp_ns
        self._last_receipt = max(now_ns, self._last_receipt + 1)
        return self._last_receipt

    def keep(self, status: Status) -> None:
        """Keep ``status`` as its request's last answer."""
        if status.request:
            self._last[status.request] = status
            self._last.move_to_end(status.request)
            while len(self._last) > self.history:
                self._last.popitem(last=False)

    def last(self, request: int) -> Optional[Status]:
        """Return the last status of ``request``, or None if it is new."""
        return self._last.get(request)


class PlannerOutput:
    """What a planner decided, in order, and the last status of each request (:class:`Answers`).

    >>> out = PlannerOutput()
    >>> out.report('queued', 7); out.repeat(7), out.repeat(8)
    (True, False)
    >>> [(c.state, c.repeated) for c in out.take()], out.take()
    ([('queued', False), ('queued', True)], [])
    """

    def __init__(self, history: int = HISTORY):
        """Nothing decided yet."""
        self.answers = Answers(history)
        self._commands: List[PlannerCommand] = []

    def send(self, command: PlannerCommand) -> None:
        """Add ``command`` to what is to be sent."""
        self._commands.append(command)

    def report(self, state: str, request: int, reason: str = '', plan: Optional[Plan] = None,
               kind: str = '') -> None:
        """Send and keep the status ``state`` of ``request`` (``plan``: its start, end, delay)."""
        status = Status(state, request, reason, None if plan is None else plan.start,
                        None if plan is None else plan.end,
                        0.0 if plan is None else plan.delay, kind)
        self.answers.keep(status)
        self._commands.append(status)

    def repeat(self, request: int) -> bool:
        """Send the last status of ``request`` again; return False if it is new."""
        last = self.answers.last(request)
        if last is not None:
            self._commands.append(replace(last, repeated=True))
        return last is not None

    def take(self) -> List[PlannerCommand]:
        """Return the commands decided since the last call, in order, and forget them."""
        out, self._commands = self._commands, []
        return out


class ArmPlanner:
    """The planner of one arm (see the module docstring): observations in, commands out.

    Every ``on_*`` method returns the commands it decided, in the order they are to be sent.

    :param arm: the arm it plans for; :param other_arm: the other arm of the cell.
    :param leader: True for the arm with priority (:mod:`scara_collab.core.planning`).
    :param settings: :class:`PlannerSettings` (may be replaced while it runs).
    :param clock: returns the sim time now, s (read again after planning: it takes time).
    :param dt: the physics step, s (the bridge's start rule, as
        :class:`~scara_collab.core.motion.Heard` applies it).
    """

    def __init__(self, arm: ArmModel, other_arm: ArmModel, leader: bool,
                 settings: PlannerSettings, clock: Callable[[], float], dt: float):
        """Nothing known yet: no joint state, nothing committed, the other arm idle."""
        self.arm, self.other_arm, self.leader = arm, other_arm, bool(leader)
        self.time = MoveTime(settings.leads)  # when its moves start, and how late they came
        self.settings = settings
        self.clock = clock
        self.joints: Optional[np.ndarray] = None        # (3,) this arm's measured joints
        self.other_joints: Optional[np.ndarray] = None  # (3,) the other arm's
        self.joints_time = 0.0                          # s, when they were measured
        self.committed: Optional[CommittedMove] = None  # this arm's move as sent
        self.queued: Optional[MoveRequest] = None       # to plan when the committed one ends
        self.settled = 0.0                              # sim s a brake brings the arm to rest
        self.blocked: Optional[MoveRequest] = None      # waiting for the other arm to move
        self.other_motion = Heard(other_arm.name, dt=dt)  # the other arm's commitments
        self.out = PlannerOutput()  # the commands decided, and the last answer to each request
        #: s: sim time minus this arm's trajectory time (the bridge's clock of it): the planner
        #: decides in trajectory time, the times its stamps and statuses carry
        self.lag = 0.0

    @property
    def settings(self) -> PlannerSettings:
        """How it plans and schedules; replaced while it runs, the start rule's leads too."""
        return self._settings

    @settings.setter
    def settings(self, settings: PlannerSettings) -> None:
        self._settings = settings
        self.time.leads = settings.leads

    def _now(self) -> float:
        """Return this arm's trajectory time now."""
        return self.clock() - self.lag

    def _other_view(self, now: float, before: Optional[float] = None) -> Timeline:
        """Return the other arm's commitments from sim time ``now``, in this arm's time.

        :param before: a start in this arm's time (the priority rule's, :meth:`Heard.motion`).
        """
        lag = self.lag
        view = self.other_motion.motion(now, self.other_joints,
                                        before=None if before is None else before + lag)
        return view.shifted(-lag) if lag else view

    # --- observations -------------------------------------------------------------------------
    def on_clock(self, own: Optional[float] = None, other: Optional[float] = None) -> None:
        """Take the bridge's trajectory clocks: this arm's lag and the other arm's, s."""
        if own is not None:
            self.lag = float(own)
        if other is not None:
            self.other_motion.on_clock(other)

    def on_joint_state(self, joints: ArrayLike, other_joints: ArrayLike,
                       stamp: float) -> List[PlannerCommand]:
        """Take both arms' joints measured at ``stamp``; plan a queued move whose turn came."""
        self.joints = np.asarray(joints, dtype=float)
        self.other_joints = np.asarray(other_joints, dtype=float)
        self.joints_time = float(stamp)
        if self.queued is not None and self.joints_time >= self.settled and (
                self.committed is None or self.joints_time - self.lag
                >= self.committed.plan.end):
            queued, self.queued = self.queued, None
            self._plan_and_schedule(queued)
        return self.out.take()

    def on_target(self, stamp_ns: int, stamp: float, target: ArrayLike, frame: str,
                  frame_error: str = '') -> List[PlannerCommand]:
        """Take a request to move the tool to ``target``.

        :param stamp_ns: the request's stamp, ns (0: start as soon as possible).
        :param stamp: the same in s (the requested start).
        :param target: ``(3,)`` m, in ``frame`` (``'world'`` or ``'base'``).
        :param frame_error: why the target's frame is not understood (``''`` if it is): the
            request is refused with it.
        """
        request = self._request_of(stamp_ns)
        if not self.out.repeat(request):
            self._take_request(request, np.asarray(target, dtype=float), frame, stamp,
                               frame_error)
        return self.out.take()

    def on_offer(self, stamp_ns: int, stamp: float, t: Optional[ArrayLike] = None,
                 q: Optional[ArrayLike] = None, qd: Optional[ArrayLike] = None,
                 qdd: Optional[ArrayLike] = None, error: str = '') -> List[PlannerCommand]:
        """Take a request offered as a plan: ``(N,)`` times from its start, ``(N, 3)`` arrays.

        The target is its last point (world). A plan that is not one (no velocities, outside
        the joint limits, ``error``: why the message could not be read) is refused.
        """
        request = self._request_of(stamp_ns)
        if self.out.repeat(request):
            return self.out.take()
        if not error:
            try:
                offer = offered_move(self.arm, t, q, qd, qdd)
            except ValueError as exc:
                error = str(exc)
        if error:
            self.out.report('refused', request, f'offered trajectory: {error}')
        else:
            self._take_request(request, fk(self.arm, offer.q[-1]), 'world', stamp, offer=offer)
        return self.out.take()

    def on_other_trajectory(self, move_id: str, stamp: float, t: ArrayLike,
                            q: ArrayLike) -> List[PlannerCommand]:
        """Take a trajectory the other arm was sent; retry a blocked move, or re-time ours.

        :param move_id: its id; :param stamp: its stamp, s (0: now); :param t: ``(N,)`` s
            from its start; :param q: ``(N, 3)``.
        """
        now = self.clock()
        if self.other_motion.trajectory(move_id, stamp, t, q, now, self.other_joints) is None:
            return self.out.take()  # it would have ended: the bridge refuses it
        if self.blocked is not None:  # the other arm moves: maybe it clears the way
            blocked = self.blocked
            self._plan_and_schedule(blocked._replace(wanted=0.0), wanted=blocked.wanted)
        elif (not self.leader and self.committed is not None
              and self.time.ahead(self.committed.plan.start, now - self.lag)):
            self._make_way(now)
        return self.out.take()

    def on_other_execution(self, state: str, move_id: str,
                           start: Optional[float] = None) -> List[PlannerCommand]:
        """Take the bridge's status of the other arm's move (:meth:`.motion.Heard.status`)."""
        self.other_motion.status(state, move_id, self.clock(), start, self.other_joints)
        return self.out.take()

    def on_own_execution(self, state: str, request: int, start: Optional[float] = None,
                         stamp: Optional[float] = None,
                         end: Optional[float] = None) -> List[PlannerCommand]:
        """Take the bridge's status of this arm's move for ``request``.

        :param start: the start it reports, s; :param stamp: the start the move asked for, s
            (None or 0: none); :param end: of ``held``, when the arm's brake brings it to rest
            (sim s): a move asked before then waits for it (planned from where it stops).

        An ``accepted`` move adds its lateness to the measured lead and, if late, is re-based
        to its real start; once refused, preempted or held nothing of it runs, so the next
        request is planned at once, except a refused re-time: the move it re-timed stays.
        """
        if state == 'held' and end is not None:
            self.settled = max(self.settled, float(end))
        if self.committed is None or request != self.committed.request:
            return self.out.take()  # not the arm's current move
        late = lateness(stamp, start) if state == 'accepted' and start is not None else 0.0
        if state == 'accepted' and stamp:
            self.time.started(stamp, start)
        retimed = self.committed.retimed
        if state == 'accepted' and retimed is not None:
            if start is not None and start < self.committed.plan.start - 1e-6:
                return self.out.take()  # the first one's word, heard after the re-time left
            self.committed = self.committed._replace(retimed=None)
        if state == 'accepted' and late > 0:
            plan = self.committed.plan
            self.committed = self.committed._replace(plan=Plan(plan.traj, start,
                                                               plan.delay + late))
            last = self.out.answers.last(request)
            self.out.report('planned', request, f'started {late:.3f} s late by the bridge',
                            self.committed.plan, '' if last is None else last.kind)
        elif state == 'refused' and retimed is not None:
            # the bridge keeps the move it was to re-time (one that had started, most likely)
            self.committed = CommittedMove(retimed, self.committed.asked, begun=True)
        elif state in NOT_RUNNING:
            self.committed = None
        return self.out.take()

    # --- decisions ----------------------------------------------------------------------------
    def _take_request(self, request: int, target: np.ndarray, frame: str, stamp: float,
                      frame_error: str = '', offer: Optional[Trajectory] = None) -> None:
        """Plan, queue or refuse the move ``request`` to ``target`` (``offer``: a plan of it)."""
        if self.joints is None or self.other_joints is None:
            self.out.report('refused', request, 'no joint state yet (is the bridge up?)')
            return
        if not np.all(np.isfinite(target)):
            self.out.report('refused', request, f'non-finite target {target.tolist()}')
            return
        if frame_error:
            self.out.report('refused', request, frame_error)
            return
        for held in (self.blocked, self.queued):  # a new request supersedes them
            if held is not None:
                self.out.report('superseded', held.request, f'replaced by request {request}')
        self.blocked = self.queued = None
        asked = MoveRequest(target, frame, stamp, offer, request)
        now = self._now()
        committed = self.committed
        if (committed is not None and committed.retimed is None and not committed.begun
                and self.time.ahead(committed.plan.start, now - self.lag)):
            # sent, but surely not begun: the new request takes its place, from where the arm
            # is (the hold drops it at the bridge, whatever becomes of the new one)
            self.committed = None
            self.out.send(HoldArm(self.joints.copy()))
            self.out.report('superseded', committed.request,
                            f'replaced by request {request} before it began')
        if self.committed is not None and self.committed.plan.end > now:
            # the bridge replaces a running trajectory: hold this one until ours has ended
            self.queued = asked
            self.out.report('queued', request, 'behind the running move (ends '
                            f't={self.committed.plan.end:.3f} s)')
            return
        if self.joints_time < self.settled:  # braking: planned from where the arm stops
            self.queued = asked
            self.out.report('queued', request, f'behind a brake (at rest t={self.settled:.3f} s)')
            return
        self._plan_and_schedule(asked)

    def _plan_and_schedule(self, asked: MoveRequest, wanted: Optional[float] = None) -> None:
        """Plan ``asked`` and schedule it against the other arm: send it, or wait, or refuse.

        :param wanted: when it was first wanted (a retried move); None: its start now.
        """
        s = self.settings
        now = self._now()
        start = self.time.wanted(asked.wanted, now)
        wanted = start if wanted is None else wanted
        if (asked.offer is not None and s.mode == 'line_or_joint'
                and starts_at(asked.offer, self.joints, s.trajectory['offer_tolerance'])):
            traj = asked.offer  # the job's plan of this move: not planned again
        else:
            try:
                traj = plan_path(self.arm, self.joints, asked.target, asked.frame, s.mode,
                                 **path_options(s.trajectory))
            except (IKError, ValueError) as exc:
                self.out.report('refused', asked.request, str(exc))
                return
        now = self.clock()
        start = self.time.sendable(start, now - self.lag)  # planning took (sim) time too
        # from now on (the past is past), by the priority rule at the start found, as the
        # door applies it (a follower move waiting to start at or after it yields); all in
        # this arm's trajectory time
        heard = self.other_motion
        waiting = heard.waiting_start
        plan = schedule_for_door(
            self.arm, traj, start, self.other_arm,
            lambda before: self._other_view(now, before),
            None if waiting is None else waiting - self.lag, s.margin,
            self.leader, s.max_delay, heard.dt)
        asked = asked._replace(wanted=wanted)
        if plan is None:
            self._wait(asked)
            return
        if plan.start - wanted > 1e-9:  # count the time spent waiting, not just the last delay
            plan = Plan(plan.traj, plan.start, plan.start - wanted)
        self.blocked = None
        self._send(plan, asked)

    def _make_way(self, now: float) -> None:
        """Re-time the follower's move that has not started for a new leader move.

        Kept if it still keeps the margin, delayed if a delay does, else the arm is held and
        the move waits for the leader.
        """
        s, move = self.settings, self.committed
        plan = schedule(self.arm, move.plan.traj, move.plan.start, self.other_arm,
                        self._other_view(now), s.margin, leader=False, max_delay=s.max_delay)
        if plan is None:
            self.committed = None
            self.out.send(HoldArm(self.joints.copy()))
            self._wait(move.asked)
        elif plan.delay > 0:
            self._send(Plan(plan.traj, plan.start, plan.start - move.asked.wanted), move.asked,
                       f're-timed for a new {self.other_arm.name} move', retimed=move.plan)

    def _wait(self, asked: MoveRequest) -> None:
        """Wait for the other arm: it blocks ``asked`` even after its committed motion."""
        s = self.settings
        waited = self._now() - asked.wanted
        if waited > s.max_wait:
            self.blocked = None
            self.out.report('refused', asked.request, f'{self.other_arm.name} has blocked the '
                            f'move for {waited:.1f} s')
            return
        first = self.blocked is None or self.blocked.request != asked.request
        self.blocked = asked
        if first:
            self.out.report('waiting', asked.request, f'{self.other_arm.name} blocks it: no start '
                            f'within {s.max_delay:.0f} s keeps {s.margin:.2f} m')

    def _send(self, plan: Plan, asked: MoveRequest, note: str = '',
              retimed: Optional[Plan] = None) -> None:
        """Commit the arm to ``plan`` for ``asked`` (re-timing ``retimed``): send it, report it."""
        self.committed = CommittedMove(plan, asked, retimed)
        self.out.send(SendMove(asked.request, plan))
        kind = 'line' if path_metrics(plan.traj).max_deviation < LINE_DEVIATION else 'joint move'
        self.out.report('planned', asked.request, note, plan, kind)

    # --- answers ------------------------------------------------------------------------------
    def _request_of(self, stamp_ns: int) -> int:
        # the receipt time in ns: the clock's s * 1e9 rounds back to the exact ns up to ~1e5 s
        return self.out.answers.request_of(int(stamp_ns), round(self.clock() * 1e9))
