"""What each arm is committed to do, and when: the one model of the bridge's execution rules.

An arm runs at most one trajectory and has at most one more waiting for its start, as
ros2_control's joint trajectory controller keeps them. The rules, written here once:

- **Start.** When a trajectory starts is the start rule's
  (:func:`scara_collab.core.move_time.start_time`): stamp 0 now, a stamp in the future then,
  one in the past now, *late*; one that would already have ended is refused. If its first
  point is after its start, the arm moves there from where it is (:func:`from_here`).
- **Replace.** A new trajectory takes over at its own start: until then the arm keeps what
  it runs (or holds), and a trajectory still waiting for its start is replaced at once
  (:meth:`ArmMotion.take`, :meth:`ArmMotion.advance`).
- **Start where the arm is.** A trajectory must begin within ``start_tolerance`` of where the
  arm is when it takes over: the measured pose for one that starts now, where the running move
  puts the arm for one that waits; a waiting move is measured again as it takes over, so the
  reference never jumps (:meth:`CellMotion.start_gap`).
- **Hold, brake.** A hold drops both and keeps a pose; a brake runs the stop at the
  acceleration limits (:func:`scara_collab.core.safety.braking`) at once
  (:meth:`ArmMotion.hold`, :meth:`ArmMotion.brake`).
- **Safe against the other arm.** A trajectory is admitted only if, against what the other
  arm is committed to (its running move, a brake included, and its waiting one), the capsules
  stay ``margin`` apart (:meth:`CellMotion.admit`). The priority rule of
  :mod:`scara_collab.core.planning` applies: the leader does not wait for a follower move
  that starts at or after its own start, because that follower move is checked again when it
  takes over (:meth:`CellMotion.advance`): a move that would start later than the moment its
  safety was judged for is judged again, never started blindly.

:class:`CellMotion` is what the bridge's simulator executes from (the servo samples the moves
it admits). Observers that only hear the trajectories and the bridge's statuses (the collision
monitor, the planners) keep the same :class:`ArmMotion` through :class:`Heard`, so every node
predicts the arms with the same rules.

- **What the bridge reports.** Each arm's *latest* move (the newest it took, until it ends,
  is dropped or held) is the one the bridge's statuses are about: taking a new one preempts
  it (:meth:`CellMotion.take`), and :meth:`CellMotion.poll` says which were dropped at their
  start and which have ended.

All times are absolute sim seconds.
"""
from dataclasses import dataclass, replace
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core import collision, safety
from scara_collab.core.model import ArmModel
from scara_collab.core.move_time import lateness, Refused, stamp_time, start_time
from scara_collab.core.planning import binds_leader, Plan, schedule, Timeline
from scara_collab.core.trajectory import Trajectory

#: s: a move whose end is this close ahead counts as ended (the bridge's polls fall on a grid)
END_SLACK = 1e-9


@dataclass(frozen=True)
class Move:
    """A trajectory an arm runs or will run.

    :ivar id: the move's name (the trajectory's ``header.frame_id``; ``''`` for none).
    :ivar timeline: its motion in absolute time.
    :ivar stamp: the start it asked for (0: now).
    :ivar ref: the executor's own form of it (the servo's reference), or None.
    :ivar braking: a stop at the acceleration limits (the bridge's own; no status is about it).
    """

    id: str
    timeline: Timeline
    stamp: float = 0.0
    ref: Any = None
    braking: bool = False

    @property
    def start(self) -> float:
        """When it takes over, s."""
        return self.timeline.start

    @property
    def end(self) -> float:
        """When it ends, s (the arm then holds its last point)."""
        return self.timeline.end

    @property
    def late(self) -> float:
        """Seconds it starts after its stamp (0 if on time or unstamped)."""
        return lateness(self.stamp, self.start)

    def shifted(self, start: float) -> 'Move':
        """Return the same move starting at ``start``."""
        return replace(self, timeline=self.timeline.shifted(start - self.start))


def schedule_for_door(me: ArmModel, traj: Trajectory, start: float, other_arm: ArmModel,
                      view: Callable[[Optional[float]], Timeline],
                      waiting: Optional[float], margin: float, leader: bool,
                      max_delay: float, dt: float) -> Optional[Plan]:
    """Schedule ``traj`` from ``start`` against the other arm as the door will judge it.

    :func:`scara_collab.core.planning.schedule`, with the priority rule applied at the start
    it finds (:meth:`CellMotion.judge` applies it at the move's start): a follower move
    waiting to start at ``waiting`` counts for a leader move that starts after it and not for
    one that starts at or before it. If the start found without it is later than it, the
    move starts after it (one step ``dt`` on at the least), against the follower's motion with
    it. Starts are on the stamp's grid (:func:`stamp_time`).

    :param view: ``view(before)``: the other arm's committed motion for a move starting at
        ``before`` (``None``: all of it), e.g. :meth:`Heard.motion`.
    :param waiting: the start of the other arm's move waiting for its start, or None.
    :return: the plan (its ``delay`` from ``start``), or None if no start within
        ``max_delay`` keeps ``margin``.
    """
    start = stamp_time(start)
    plan = schedule(me, traj, start, other_arm, view(start if leader else None), margin, leader,
                    max_delay)
    if (leader and waiting is not None and not binds_leader(waiting, start)
            and (plan is None or binds_leader(waiting, stamp_time(plan.start)))):
        after = stamp_time(max(waiting + dt, start))
        plan = None if after - start > max_delay else schedule(
            me, traj, after, other_arm, view(after), margin, leader, max_delay - (after - start))
    if plan is None:
        return None
    at = stamp_time(plan.start)
    return Plan(traj, at, at - start)


def from_here(t: np.ndarray, q: np.ndarray, q_now: Optional[ArrayLike],
              qd: Optional[np.ndarray] = None, qdd: Optional[np.ndarray] = None,
              qd_now: Optional[ArrayLike] = None) -> Tuple[np.ndarray, np.ndarray,
                                                           Optional[np.ndarray],
                                                           Optional[np.ndarray]]:
    """Return a trajectory whose first point after ``t = 0`` is reached from where the arm is.

    As ros2_control's joint trajectory controller: ``(q_now, qd_now)`` becomes the point at
    ``t = 0`` (at rest if ``qd_now`` is None; no acceleration); a trajectory that begins at
    ``t = 0``, or an arm whose pose is unknown (``q_now`` None), is returned as it is.

    :param t: ``(N,)`` s from the start; :param q, qd, qdd: ``(N, 3)`` (``qd``, ``qdd`` or None).
    :return: ``(t, q, qd, qdd)``.
    """
    if t[0] <= 0.0 or q_now is None:
        return t, q, qd, qdd
    t = np.concatenate(([0.0], t))
    q = np.vstack([np.asarray(q_now, dtype=float).reshape(1, 3), q])
    if qd is not None:
        qd = np.vstack([np.zeros((1, 3)) if qd_now is None
                        else np.asarray(qd_now, dtype=float).reshape(1, 3), qd])
    if qdd is not None:
        qdd = np.vstack([np.zeros(3), qdd])
    return t, q, qd, qdd


def resolve(move_id: str, stamp: float, t: ArrayLike, q: ArrayLike, now: float, dt: float,
            q_now: Optional[ArrayLike] = None) -> Move:
    """Return the move a trajectory makes, received at ``now`` (the start rule, :func:`from_here`).

    :param t: ``(N,)`` times from the start, s; :param q: ``(N, 3)`` joint positions.
    :param q_now: ``(3,)`` where the arm is: it moves from there to a first point later than
        ``t = 0``; None if unknown (then the first point is held until it is reached).
    :raises Refused: it would have ended before ``now``.
    """
    t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float).reshape(-1, 3)
    start = start_time(stamp, float(t[-1]), now, dt)
    t, q, _, _ = from_here(t, q, q_now)
    return Move(move_id, Timeline(start + t, q), float(stamp))


def splice(before: Timeline, after: Timeline) -> Timeline:
    """Return ``before`` until ``after`` starts, then ``after`` (a move taking over)."""
    keep = before.t < after.start
    if not np.any(keep):
        return after
    return Timeline(np.concatenate([before.t[keep], after.t]),
                    np.vstack([before.q[keep], after.q]))


class ArmMotion:
    """One arm's commitments: the move it runs and the one waiting for its start.

    Its moves run on the arm's own trajectory clock (:attr:`lag`): their times (a move's
    start, end and timeline, a trajectory's stamp) are trajectory time, which runs behind sim
    time by the lag that speed scaling has built up (0 when nothing has been slowed). Every
    method takes sim time (``now``) and returns timelines in sim time, the arm's motion as it
    will be if its clock runs at full speed from ``now`` on.

    :param name: the arm; :param q: ``(3,)`` the pose it holds.
    """

    def __init__(self, name: str, q: ArrayLike):
        """Start with nothing committed: the arm holds ``q``; its clock on sim time."""
        self.name = name
        self.running: Optional[Move] = None
        self.waiting: Optional[Move] = None
        self.rest = np.asarray(q, dtype=float).reshape(3).copy()
        #: the newest move taken, until it ends, is dropped or held: what statuses are about
        self.latest: Optional[Move] = None
        #: s: sim time minus the arm's trajectory time (what speed scaling has cost it)
        self.lag = 0.0

    def clock(self, now: float) -> float:
        """Return the arm's trajectory time at sim time ``now``."""
        return now - self.lag

    def in_sim(self, timeline: Timeline) -> Timeline:
        """Return ``timeline`` (trajectory time) in sim time, at full speed from now on."""
        return timeline.shifted(self.lag) if self.lag else timeline

    def take(self, move: Move, now: float) -> Optional[Move]:
        """Commit to ``move``; return the move it replaces at once, if any.

        A move that starts later waits, replacing a waiting one; one that starts now replaces
        the running one and the waiting one.
        """
        self.latest = move
        if move.start > self.clock(now):
            old, self.waiting = self.waiting, move
            return old
        old = self.waiting or self.running
        self.running, self.waiting = move, None
        return old

    def advance(self, now: float) -> List[Tuple[str, Move]]:
        """Move on to sim time ``now``: ``('started', move)`` and ``('finished', move)`` events."""
        out = []
        now = self.clock(now)
        if self.waiting is not None and now >= self.waiting.start:
            if self.running is not None:
                self.rest = self.running.timeline.at(now)
            self.running, self.waiting = self.waiting, None
            out.append(('started', self.running))
        if self.running is not None and now >= self.running.end:
            done, self.running = self.running, None
            self.rest = done.timeline.q[-1].copy()
            out.append(('finished', done))
        return out

    def hold(self, q: ArrayLike) -> List[Move]:
        """Drop both moves and hold ``q``; return the moves dropped."""
        dropped = [m for m in (self.running, self.waiting) if m is not None]
        self.running = self.waiting = self.latest = None
        self.rest = np.asarray(q, dtype=float).reshape(3).copy()
        return dropped

    def brake(self, arm: ArmModel, q: ArrayLike, qd: ArrayLike, now: float,
              dt: float = 0.01, ref_of=None) -> Move:
        """Stop from ``(q, qd)`` at the acceleration limits, at once; return the brake move.

        The stop runs on the arm's clock from ``now`` at full speed: a stop is never slowed.

        :param ref_of: makes the executor's form of the stop from ``(t, q, qd, qdd)``.
        """
        t, pos, vel, acc = safety.braking(arm, q, qd, dt)
        t = self.clock(now) + t
        move = Move('', Timeline(t, pos), 0.0,
                    None if ref_of is None else ref_of(t, pos, vel, acc), braking=True)
        self.hold(q)
        self.running = move
        return move

    def active(self, now: float) -> bool:
        """Return True while the arm has a move to run (also one waiting for its start)."""
        return self.waiting is not None or (self.running is not None
                                            and self.clock(now) < self.running.end)

    def current(self, now: float, q: Optional[ArrayLike] = None) -> Timeline:
        """Return what the arm does from ``now`` without its waiting move (sim time).

        :param q: ``(3,)`` the measured pose, for an arm that holds (default its last pose).
        """
        if self.running is not None and self.running.end > self.clock(now):
            return self.in_sim(self.running.timeline).since(now)
        return Timeline.hold(now, self.rest if q is None else q)

    def motion(self, now: float, q: Optional[ArrayLike] = None,
               before: Optional[float] = None) -> Timeline:
        """Return everything the arm is committed to from ``now``: the running, then the waiting.

        :param before: the start of a leader's move that this arm (a follower) must make way
            for: a waiting move starting at or after it is left out (the priority rule,
            :func:`scara_collab.core.planning.binds_leader`), and the arm runs what it runs:
            that move is judged again against the leader's when it would take over and, if
            dropped then, the arm goes on with its running move. None: everything counts.
        """
        now_on = self.current(now, q)
        w = self.waiting
        if w is None or (before is not None and not binds_leader(w.start + self.lag, before)):
            return now_on
        return splice(now_on, self.in_sim(w.timeline).since(now))

    @property
    def waiting_start(self) -> Optional[float]:
        """Return the sim time the move waiting for its start starts at (None: none)."""
        return None if self.waiting is None else self.waiting.start + self.lag


@dataclass(frozen=True)
class Check:
    """How a move was judged against the other arm.

    :ivar ok: admitted; :ivar reason: why not (``''`` if admitted).
    :ivar breach: the first predicted time within the margin, or None.
    """

    ok: bool
    reason: str = ''
    breach: Optional[float] = None


class CellMotion:
    """Every arm's commitments and the admission rule between them (module docstring).

    :param arms: the arms, the leader first.
    :param q: ``(arms, 3)`` the poses they hold.
    :param margin: m between capsule surfaces that an admitted move keeps.
    :param dt: the physics step, s (the start rule's slack).
    :param step: s between predicted samples (:func:`scara_collab.core.safety.first_breach`).
    :param start_tolerance: rad | m a move may begin away from where the arm is
        (:meth:`start_gap`); None: not checked.
    """

    def __init__(self, arms: Sequence[ArmModel], q: ArrayLike, margin: float, dt: float,
                 step: float = safety.PREDICTION_STEP, start_tolerance: Optional[float] = None):
        """Every arm holds its pose in ``q``."""
        self.models = {a.name: a for a in arms}
        self.leader = arms[0].name
        self.arms: Dict[str, ArmMotion] = {a.name: ArmMotion(a.name, p)
                                           for a, p in zip(arms, np.asarray(q, dtype=float))}
        self.margin, self.dt, self.step = float(margin), float(dt), float(step)
        self.start_tolerance = start_tolerance
        self.checking = True  # False: admit without the check (an arm alone)
        self._dropped: List[Tuple[str, str, Move, str]] = []  # since the last poll

    def __getitem__(self, robot: str) -> ArmMotion:
        """Return ``robot``'s commitments."""
        return self.arms[robot]

    def others(self, robot: str) -> List[str]:
        """Return the other arms' names."""
        return [r for r in self.arms if r != robot]

    def start_gap(self, robot: str, move: Move, now: float, q: Dict[str, np.ndarray]) -> str:
        """Return why ``move`` would not begin where ``robot`` is when it takes over, or ``''``.

        Where the arm is then: the measured pose ``q[robot]`` for a move that starts now (or
        takes over now), else where its running move puts it at the move's start. A move
        that begins elsewhere would make the reference jump: the controller then chases it
        at its torque limits, faster than any trajectory the arm was admitted for.
        """
        if self.start_tolerance is None:
            return ''
        arm = self.arms[robot]
        at = max(arm.clock(now), move.start)  # trajectory time
        if at <= arm.clock(now):
            there, where = np.asarray(q[robot], dtype=float), 'the measured position'
        else:
            there = arm.current(now, q.get(robot)).at(at + arm.lag)
            where = f'where its running move puts the arm at its start (t={at:.3f} s)'
        gap = np.abs(move.timeline.at(at) - there)
        j = int(np.argmax(gap))
        if gap[j] <= self.start_tolerance:
            return ''
        return (f'the trajectory starts {gap[j]:.4f} away from {where} of joint {j + 1} '
                f'({there[j]:.4f}); at most {self.start_tolerance} is allowed')

    def judge(self, robot: str, move: Move, now: float, q: Dict[str, np.ndarray]) -> Check:
        """Judge ``move`` of ``robot`` against every other arm's commitments from ``now``.

        ``robot`` runs what it runs until ``move`` starts, then ``move``. The leader's view of
        a follower leaves out a follower move waiting to start at or after the leader's
        start. Arms already within the margin (stopped too close) may only be parted: the
        move must take ``robot`` away from arms that stand still
        (:func:`scara_collab.core.safety.separating`).

        :param q: ``{robot: (3,)}`` the measured poses.
        """
        if not self.checking:
            return Check(True)
        me, arm = self.models[robot], self.arms[robot]
        mine = splice(arm.current(now, q.get(robot)), arm.in_sim(move.timeline).since(now))
        start = move.start + arm.lag  # sim time
        for other in self.others(robot):
            view = self.arms[other].motion(now, q.get(other),
                                           before=start if robot == self.leader else None)
            d_now = float(collision.arm_distance(me, mine.at(now), self.models[other],
                                                 view.at(now)))
            if d_now < self.margin:
                still = view.end <= now
                if still and safety.separating(me, np.vstack([mine.at(now), move.timeline.q]),
                                               self.models[other], view.at(now)):
                    continue
                return Check(False, f'{robot} and {other} are {d_now:.3f} m apart now (< '
                             f'{self.margin} m): only a move that parts them from an arm '
                             'standing still is run', now)
            breach = safety.first_breach(me, mine, self.models[other], view, self.margin, now,
                                         self.step)
            if breach is not None:
                what = (f'its running move {self.arms[other].running.id or "(brake)"}'
                        if self.arms[other].running is not None else 'where it stands')
                return Check(False, f'it would bring {robot} within {self.margin} m of {other} '
                             f'({what}{" and its next move" if self.arms[other].waiting else ""})'
                             f' at t={breach:.3f} s', breach)
        return Check(True)

    def take(self, robot: str, move: Move, now: float, q: Dict[str, np.ndarray]) -> Optional[Move]:
        """Admit ``move`` (:meth:`judge`) and commit ``robot`` to it (:meth:`ArmMotion.take`).

        :return: the move it preempts: the arm's latest (:attr:`ArmMotion.latest`), if that is
            another move (a move sent again under its own id preempts nothing).
        :raises Refused: with the reason, if it would break the margin; nothing changes.
        """
        check = self.judge(robot, move, now, q)
        if not check.ok:
            raise Refused(check.reason)
        arm = self.arms[robot]
        old = arm.latest
        arm.take(move, now)
        return old if old is not None and old.id != move.id else None

    def advance(self, now: float, q: Dict[str, np.ndarray]) -> List[Tuple[str, str, Move, str]]:
        """Move every arm on to ``now``, judging each waiting move again as it takes over.

        The leader goes first, so a follower move taking over at the same instant is judged
        against the leader's. A waiting move that no longer begins where the arm is
        (:meth:`start_gap`) or no longer keeps the margin is dropped (the arm keeps what it
        ran).

        :return: ``(robot, event, move, reason)``: ``started``, ``finished``, or ``dropped``
            with the reason.
        """
        out = []
        for robot, arm in self.arms.items():
            w = arm.waiting
            if w is not None and arm.clock(now) >= w.start:
                reason = self.start_gap(robot, w, now, q) or self.judge(robot, w, now, q).reason
                if reason:
                    arm.waiting = None
                    out.append((robot, 'dropped', w, f'judged again at its start: {reason}'))
                    self._dropped.append(out[-1])
            out.extend((robot, ev, m, '') for ev, m in arm.advance(now))
        return out

    def poll(self, now: float) -> List[Tuple[str, str, Move, str]]:
        """Return what happened to the arms' latest moves by ``now``, in the order to report it.

        First the moves dropped at their start since the last poll (:meth:`advance`), then
        every latest move whose end has come (``finished``, within :data:`END_SLACK`); neither
        is the arm's latest any more.

        :return: ``(robot, event, move, reason)``, event ``dropped`` or ``finished``.
        """
        out, self._dropped = self._dropped, []
        for robot, _, move, _ in out:
            if self.arms[robot].latest is not None and self.arms[robot].latest.id == move.id:
                self.arms[robot].latest = None
        for robot, arm in self.arms.items():
            if arm.latest is not None and arm.clock(now) >= arm.latest.end - END_SLACK:
                out.append((robot, 'finished', arm.latest, ''))
                arm.latest = None
        return out

    def release(self, robot: str) -> str:
        """Forget ``robot``'s latest move (the arm is held); return its id (``''``: none)."""
        arm = self.arms[robot]
        move, arm.latest = arm.latest, None
        return '' if move is None else move.id


@dataclass
class Booking:
    """A move asked for and not heard yet, as its asker planned it (:meth:`Heard.book`).

    :ivar request: the request it answers.
    :ivar timeline: the asker's plan of it from its start; None until it can be planned.
    :ivar counts: its planner has it in hand (asked, planned or accepted; not queued, waiting,
        refused or ended): the arm is committed to it.
    :ivar heard: its trajectory came: what was heard is the commitment from then on.
    """

    request: int
    timeline: Optional[Timeline] = None
    counts: bool = True
    heard: bool = False


class Heard:
    """One arm's commitments as a node hears them: its trajectories, then the bridge's word.

    A trajectory is taken as the bridge will take it (:func:`resolve`, :meth:`ArmMotion.take`)
    as soon as it is heard; the bridge's status corrects it: ``accepted`` moves it to the
    start the bridge gives (heard before the trajectory too: kept until it comes),
    ``refused`` undoes it, ``held`` holds the arm, ``finished`` ends it. A node that asks for
    moves itself (the sorting job) books each one as it asked it (:meth:`book`), so that in
    the time before its trajectory is heard the arm is not taken to stand still
    (:meth:`committed`).

    :param name: the arm; :param q: ``(3,)`` where it is; :param dt: the physics step, s.
    """

    def __init__(self, name: str, q: ArrayLike = (0.0, 0.0, 0.0), dt: float = 0.001):
        """Nothing heard yet: the arm holds ``q``."""
        self.arm = ArmMotion(name, q)
        self.dt = float(dt)
        self._undo: Dict[str, Tuple[Optional[Move], Optional[Move]]] = {}
        self._early: Dict[str, float] = {}  # move id -> its start, accepted before heard
        #: the move asked for and not heard yet (:meth:`book`), or None
        self.booked: Optional[Booking] = None

    def book(self, request: int, timeline: Optional[Timeline]) -> None:
        """Book the move just asked for ``request``, as planned (``timeline``; None: unknown).

        It replaces any earlier booking, and stands until its trajectory is heard
        (:meth:`trajectory` with its request), the asker withdraws it (:attr:`booked` None)
        or says it does not count (:attr:`Booking.counts`).
        """
        self.booked = Booking(int(request), timeline)

    def trajectory(self, move_id: str, stamp: float, t: ArrayLike, q: ArrayLike, now: float,
                   q_now: Optional[ArrayLike] = None,
                   request: Optional[int] = None) -> Optional[Move]:
        """Take a trajectory heard at ``now``; return its move (None: the bridge refuses it).

        :param request: the booked request it answers (:meth:`book`), if any.
        """
        try:
            move = resolve(move_id, stamp, t, q, self.arm.clock(now), self.dt, q_now)
        except Refused:
            return None
        early = self._early.pop(move_id, None)
        if early is not None and move_id:
            move = move.shifted(early)
        self._undo = {move_id: (self.arm.running, self.arm.waiting)}
        self.arm.take(move, now)
        if request is not None and self.booked is not None and self.booked.request == request:
            self.booked.heard = True
        return move

    def committed(self, now: float, q: Optional[ArrayLike] = None) -> Timeline:
        """Return what the arm is committed to from ``now``: a booking that counts, else heard.

        A booked move that counts, is not heard yet and has not ended is the arm's commitment
        as its asker planned it; otherwise :meth:`motion`.
        """
        b = self.booked
        if (b is not None and b.counts and not b.heard and b.timeline is not None
                and b.timeline.end > self.arm.clock(now)):
            return self.arm.in_sim(b.timeline)
        return self.motion(now, q)

    def on_clock(self, lag: float) -> None:
        """Take the arm's trajectory clock as the bridge reports it: ``lag`` s behind sim time."""
        self.arm.lag = float(lag)

    def status(self, state: str, move_id: str, now: float, start: Optional[float] = None,
               q: Optional[ArrayLike] = None) -> bool:
        """Take the bridge's status of a move at ``now``; return True if anything changed.

        :param start: the start it reports (``accepted``); :param q: the arm's pose now.
        """
        arm = self.arm
        if state == 'accepted' and start is not None:
            m = next((m for m in (arm.waiting, arm.running) if m is not None and m.id == move_id),
                     None)
            if m is None:
                self._early[move_id] = start
                return False
            if abs(m.start - start) < 1e-9:
                return False
            moved = m.shifted(start)
            if arm.running is m:
                arm.running = moved
            elif moved.start > arm.clock(now):
                arm.waiting = moved
            else:
                arm.running, arm.waiting = moved, None
            return True
        if state == 'refused' and move_id in self._undo:
            arm.running, arm.waiting = self._undo.pop(move_id)
            return True
        if state == 'held':
            arm.hold(arm.rest if q is None else q)
            return True
        if state == 'finished' and arm.running is not None and arm.running.id == move_id:
            arm.advance(max(now, arm.running.end + arm.lag))
            return True
        return False

    @property
    def waiting_start(self) -> Optional[float]:
        """Return the sim time the arm's move waiting for its start starts at; None: none."""
        return self.arm.waiting_start

    def motion(self, now: float, q: Optional[ArrayLike] = None,
               before: Optional[float] = None) -> Timeline:
        """Return the arm's commitments from ``now`` (:meth:`ArmMotion.motion`)."""
        self.arm.advance(now)
        return self.arm.motion(now, q, before)

    def current(self, now: float, q: Optional[ArrayLike] = None) -> Timeline:
        """Return what the arm runs from ``now``, without a move waiting for its start."""
        self.arm.advance(now)
        return self.arm.current(now, q)
