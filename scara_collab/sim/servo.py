"""The arms' servo, without PyBullet: the reference each arm follows and the law that tracks it.

Each arm follows a reference: a hold (its last point at rest) or a trajectory
(:class:`scara_collab.sim.reference.HermiteReference`, from its start time on; until then the
arm keeps the reference it had, as ros2_control's trajectory controller replaces a trajectory
at the new one's start). Which trajectory runs, from when, and whether it may run at all next
to the other arm is decided by the cell's committed-motion model
(:class:`scara_collab.core.motion.CellMotion`, :attr:`Servo.motion`): a trajectory that would
bring the arms within its margin is refused, and one waiting for its start is judged again
when it takes over. At every servo tick :meth:`Servo.update` samples both references and
evaluates the control law for both arms at once (:mod:`scara_collab.sim.controllers`: PID on
torque, or computed torque with one vectorised inverse-dynamics call), clamped to the effort
limits; the simulator applies :attr:`Servo.tau` until the next tick.

The emergency stop is the servo's too (:meth:`Servo.set_estop`): every arm brakes at its
acceleration limits (:func:`scara_collab.core.safety.braking`) and holds, and while it is set
a new trajectory is run only if it parts the arms (:meth:`Servo.check_recovery`).

**Speed scaling.** An arm asked to run at a factor ``s < 1`` (:meth:`Servo.scale`) gets a
trajectory clock of its own (:class:`scara_collab.core.scaled_clock.ScaledClock`): its
trajectory time advances at ``s`` (changed only as fast as the joints' acceleration limits
allow), its references are sampled at that time and scaled by the chain rule, and a move
waiting for its start starts when that clock reaches the start. The committed-motion model
keeps the lag each clock has built up (:attr:`scara_collab.core.motion.ArmMotion.lag`). A
brake is never slowed. An arm whose clock could not slow down as fast as braking would have
(:attr:`scara_collab.core.scaled_clock.ScaledSample.held_back`) is named in
:attr:`Servo.held_back` for the simulator's owner to brake. An arm never slowed has no clock
and runs on sim time, as before any scaling.
"""
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core import safety
from scara_collab.core.collision import paths_apart
from scara_collab.core.model import ArmModel
from scara_collab.core.motion import CellMotion, Move
from scara_collab.core.planning import Timeline
from scara_collab.core.scaled_clock import ScaledClock
from scara_collab.sim.controllers import ComputedTorqueController, joint_gains, PidController
from scara_collab.sim.reference import HermiteReference, TrajectoryError, validate_trajectory

CONTROL_MODES = ('pid', 'computed_torque')
#: s between two looks at whether arms running together may run apart again
RECHECK = 0.1


class Servo:
    """Both arms' references and control law (see the module docstring).

    :param arms: the arms, in the simulator's order.
    :param ctl_cfg: ``controllers.yaml`` parameters (``pid``, ``computed_torque`` gains).
    :param control_mode: ``'pid'`` or ``'computed_torque'``.
    :param gravity: m/s², downwards (positive).
    :param friction_smoothing: the Coulomb friction's tanh scale (computed torque's model).
    :param dt: s between servo ticks (the PID's integration step).
    :param q: ``(arms, 3)`` the joints now: each arm holds them.
    :param velocity_tolerance: relative slack on the velocity limits of a trajectory.
    :param start_tolerance: rad | m, how far a trajectory may start from the measured joints.
    :param margin: m the arms' commitments keep (:class:`~scara_collab.core.motion.CellMotion`);
        0 admits every valid trajectory.
    :param physics_dt: s per physics step (the model's start rule).
    :raises ValueError: for an unknown ``control_mode``.
    """

    def __init__(self, arms: Sequence[ArmModel], ctl_cfg: dict, control_mode: str,
                 gravity: float, friction_smoothing: float, dt: float, q: np.ndarray,
                 velocity_tolerance: float = 0.01, start_tolerance: float = 0.05,
                 margin: float = 0.0, physics_dt: float = 0.001):
        """Make both control laws; every arm holds ``q``."""
        if control_mode not in CONTROL_MODES:
            raise ValueError(f'control_mode must be one of {CONTROL_MODES}, '
                             f'got {control_mode!r}')
        self.arms, self.control_mode, self.dt = tuple(arms), control_mode, float(dt)
        self.velocity_tolerance, self.start_tolerance = velocity_tolerance, start_tolerance
        self.estop = False
        self.effort = np.stack([a.max_effort for a in arms])
        pid = ctl_cfg['pid']
        self._pid = PidController(joint_gains(pid, 'kp'), joint_gains(pid, 'ki'),
                                  joint_gains(pid, 'kd'), self.effort, len(arms))
        self._ct = ComputedTorqueController(
            arms, joint_gains(ctl_cfg['computed_torque'], 'kp'),
            joint_gains(ctl_cfg['computed_torque'], 'kd'), g=gravity,
            friction_smoothing=friction_smoothing)
        self.names = tuple(a.name for a in arms)
        self.motion = CellMotion(arms, q, margin, physics_dt, start_tolerance=start_tolerance)
        self.motion.checking = margin > 0
        self.tau = np.zeros((len(arms), 3))
        self.ref_q = np.array(q, dtype=float)
        self.ref_qd = np.zeros_like(self.ref_q)
        self.ref_qdd = np.zeros_like(self.ref_q)
        #: each arm's speed factor asked (:meth:`scale`), 1 = full speed
        self.factors: Dict[str, float] = {name: 1.0 for name in self.names}
        #: the trajectory clocks of the arms slowed at least once
        self.clocks: Dict[str, ScaledClock] = {}
        #: arms whose path-keeping stop fell behind braking at the last tick (their owner brakes)
        self.held_back: List[str] = []
        #: ``(arms, 3)`` each slowed arm's trajectory velocity at its trajectory time, unscaled
        self.planned = np.zeros_like(self.ref_q)
        #: how the arms' factors apply (:meth:`_run_clocks`): ``'cell'``, one factor for every
        #: arm, their clocks at one rate; ``'arm'``, each arm its own while the arms' committed
        #: paths stay apart, as ``'cell'`` while they could meet
        self.coupling = 'cell'
        #: whether the clocks ran together at the last tick (:meth:`_coupled`)
        self.coupled = False
        self._apart: Optional[Tuple[tuple, float, bool]] = None  # (moves, when, apart)
        #: the stop a clock's slowdown must keep up with, in braking times (the monitor's)
        self.stop_allowance = 1.0

    def speed(self, robot: str) -> float:
        """Return the factor ``robot``'s trajectory runs at now (1: full speed, or no clock)."""
        clock = self.clocks.get(robot)
        return 1.0 if clock is None else clock.scale

    def scale(self, robot: str, factor: float) -> None:
        """Ask ``robot``'s trajectories to run at ``factor`` of their speed, in [0, 1]."""
        self.factors[robot] = min(max(float(factor), 0.0), 1.0)

    def update(self, now: float, q: np.ndarray, qd: np.ndarray, payload: np.ndarray) -> None:
        """Sample the references at ``now`` (s) and set :attr:`tau` for the measured state.

        :param q, qd: ``(arms, 3)`` measured joints; :param payload: kg held per arm.
        """
        poses = dict(zip(self.names, q))
        self._run_clocks(now)
        ended = {}
        for robot, event, move, _ in self.motion.advance(now, poses):
            if event == 'finished':
                ended[robot] = move  # sampled once more: its last point, at rest
        for a, robot in enumerate(self.names):
            move = self.motion[robot].running or ended.get(robot)
            clock = self.clocks.get(robot)
            at = now if clock is None else clock.tau
            if move is None or move.ref is None or at < move.start:
                continue
            if clock is None:
                self.ref_q[a], self.ref_qd[a], self.ref_qdd[a] = move.ref.sample(now)
            else:  # the chain rule: the path at tau, run at s
                pos, vel, acc = move.ref.sample(at)
                self.planned[a] = vel
                s, rate = clock.scale, clock.rate
                if s == 1.0 and rate == 0.0:  # coasting: the path as planned, only later
                    self.ref_q[a], self.ref_qd[a], self.ref_qdd[a] = pos, vel, acc
                    continue
                self.ref_q[a], self.ref_qd[a] = pos, vel * s
                self.ref_qdd[a] = acc * s * s + vel * rate
        if self.control_mode == 'pid':
            tau = self._pid(q, qd, self.ref_q, self.ref_qd, self.dt)
        else:
            tau = self._ct(q, qd, self.ref_q, self.ref_qd, self.ref_qdd, payload)
        self.tau = np.minimum(np.maximum(tau, -self.effort), self.effort)

    def _run_clocks(self, now: float) -> None:
        """Advance every slowed arm's trajectory clock to ``now``; keep its lag in the model.

        The arms get their clocks when one is first asked to run below full speed. A factor
        moves towards the one asked as fast as the arm's running trajectory allows (a brake runs
        at full speed, at once); an arm that holds has nothing to keep, so its factor follows
        at once and its clock keeps its lag: an arm with nothing to do is not set back by a
        slowdown. While the arms run together (:meth:`_coupled`: the arms' moves scheduled
        against each other could meet) every arm takes the smallest factor asked, and once
        their factors are one, one rate, the smallest any arm's trajectory allows, so their
        trajectory times keep in step: what was safe between them at full speed stays so.
        """
        self.held_back = []
        if all(f >= 1.0 for f in self.factors.values()) and all(
                c.steady for c in self.clocks.values()):
            for robot, clock in self.clocks.items():  # full speed asked and run: only time
                clock.coast(now)
                self._keep_lag(robot, clock, now)
            return
        ticks = []
        for a, robot in enumerate(self.names):
            clock = self.clocks.get(robot)
            if clock is None:
                arm = self.arms[a]
                clock = self.clocks[robot] = ScaledClock(
                    now, arm.max_velocity, arm.max_acceleration,
                    stop_allowance=self.stop_allowance)
            running = self.motion[robot].running
            if running is not None and running.braking:
                clock.full_speed()
            sample = (running.ref.sample if running is not None and running.ref is not None
                      else _holding)
            ticks.append((robot, clock, sample, running is not None and running.braking))
        self.coupled = self._coupled(now)
        low = min(self.factors.values())
        targets = {r: low if self.coupled else self.factors[r] for r in self.names}
        rate = None
        if self.coupled:
            busy = [(c, f) for r, c, f, braking in ticks
                    if not braking and not self._idle(r)]
            for r, c, _, braking in ticks:  # an arm at rest keeps in step at once
                if self._idle(r) and busy:
                    c.scale = busy[0][0].scale
            if len({c.scale for c, _ in busy}) <= 1:  # in step: one rate (else each falls)
                rate = min((c.feasible(now, low, f) for c, f in busy), key=abs, default=None)
        for robot, clock, sample, braking in ticks:
            cmd = clock.tick(now, targets[robot], sample, None if braking else rate)
            self._keep_lag(robot, clock, now)
            if cmd.held_back:
                self.held_back.append(robot)

    def _keep_lag(self, robot: str, clock: ScaledClock, now: float) -> None:
        """Put ``robot``'s clock's lag in the motion model (an idle arm's clock keeps it)."""
        motion = self.motion[robot]
        if self._idle(robot):  # nothing committed: nothing to fall behind on
            clock.tau = now - motion.lag
            self.planned[self.names.index(robot)] = 0.0
        motion.lag = clock.lag

    def _coupled(self, now: float) -> bool:
        """Return True if the arms' clocks must run together now.

        Always with :attr:`coupling` ``'cell'``. With ``'arm'``, while the arms' committed
        motions (running and waiting moves, or the pose held) could come within the margin
        at some timing of one against the other
        (:func:`scara_collab.core.collision.paths_apart`): apart, each arm may run at its own
        factor, however far one falls behind. Judged again when a move is taken, started,
        finished or dropped, and every :data:`RECHECK` s while they run together (what is left
        of the paths shrinks).
        """
        if self.coupling == 'cell' or len(self.arms) < 2:
            return True
        key = tuple(id(m) for r in self.names
                    for m in (self.motion[r].running, self.motion[r].waiting))
        if (self._apart is not None and self._apart[0] == key
                and (self._apart[2] or now - self._apart[1] < RECHECK)):
            return not self._apart[2]
        paths = [self.motion[r].motion(now, self.ref_q[a]).q
                 for a, r in enumerate(self.names)]
        apart = all(paths_apart(self.arms[a], paths[a], self.arms[b], paths[b],
                                self.motion.margin)
                    for a in range(len(self.arms)) for b in range(a + 1, len(self.arms)))
        self._apart = (key, now, apart)
        return not apart

    def planned_ahead(self, robot: str, now: float, horizon: float,
                      samples: int = 5) -> np.ndarray:
        """Return per joint the planned velocity of largest size over the next ``horizon`` s.

        Unscaled, on the arm's trajectory clock (or sim time), from its running move and the
        one waiting for its start; zeros for an arm with nothing to run. What the arm may
        reach before a slowdown decided now takes hold, ``(3,)``.
        """
        motion = self.motion[robot]
        clock = self.clocks.get(robot)
        tau = now if clock is None else clock.tau
        moves = [m for m in (motion.running, motion.waiting)
                 if m is not None and m.ref is not None]
        out = [0.0, 0.0, 0.0]
        if not moves:
            return np.array(out)
        step = horizon / (samples - 1) if samples > 1 else 0.0
        for k in range(samples):  # plain floats: the times of tau + np.linspace(0, horizon)
            at = tau + (horizon if k == samples - 1 else k * step)
            move = next((m for m in reversed(moves) if m.start <= at), None)
            if move is None:
                continue
            for j, v in enumerate(np.asarray(move.ref.sample(at)[1], dtype=float).tolist()):
                if abs(v) > abs(out[j]):  # the first of largest size
                    out[j] = v
        return np.array(out)

    def _idle(self, robot: str) -> bool:
        """Return True if ``robot`` has nothing committed (no move running or waiting)."""
        motion = self.motion[robot]
        return motion.running is None and motion.waiting is None

    def execute(self, a: int, t: ArrayLike, q: ArrayLike, qd: Optional[ArrayLike],
                qdd: Optional[ArrayLike], q_now: np.ndarray, qd_now: np.ndarray,
                now: float, move_id: str = '', stamp: float = 0.0) -> Optional[Move]:
        """Run a joint trajectory on arm ``a``, replacing the running one from ``t[0]`` on.

        Until ``t[0]`` the arm keeps its reference (the hold, or the running trajectory), as
        ros2_control's trajectory controller replaces a trajectory at the new one's start; so
        what the arm does never depends on when, before its start, a trajectory arrived (in
        lockstep, at either end of a window: docs/realtime.md, *Repeatable runs*). Between
        points the reference is the cubic Hermite spline of positions and velocities (velocities by
        central finite differences, zero at both ends, if not given; accelerations its
        derivative unless given); after ``t[-1]`` it holds the last point. While the emergency
        stop is set, only a move that takes this arm away from the other one, standing still,
        is run (:meth:`check_recovery`): the way to part arms that stopped too close.

        :param t: ``(N,)`` absolute sim times, s, strictly increasing.
        :param q: ``(N, 3)`` joint positions; :param qd, qdd: ``(N, 3)`` or ``None``.
        :param q_now, qd_now: ``(arms, 3)`` the measured joints now; :param now: sim time, s.
        :param move_id: the move's name; :param stamp: the start it asked for (0: now).
        :return: the move it preempts (:meth:`scara_collab.core.motion.CellMotion.take`).
        :raises TrajectoryError: (a ``ValueError``) with the reason: emergency stop active and
            the move not separating, bad shape, non-finite value, non-increasing times, a
            position outside the joint limits, a velocity above the limits (also between
            points), or a start more than ``start_tolerance`` away from where the arm is when it
            takes over (:meth:`scara_collab.core.motion.CellMotion.start_gap`).
            :class:`scara_collab.core.motion.Refused` (a ``ValueError`` too): it would bring
            the arms within the margin. The arm keeps doing what it did.
        """
        arm = self.arms[a]
        valid = validate_trajectory(t, q, qd, arm.lower, arm.upper, arm.max_velocity,
                                    self.velocity_tolerance, qdd=qdd)
        if self.estop:
            self.check_recovery(a, valid.q, q_now, qd_now, now)
        move = Move(move_id, Timeline(valid.t, valid.q), float(stamp), HermiteReference(*valid))
        poses = dict(zip(self.names, q_now))
        gap = self.motion.start_gap(self.names[a], move, now, poses)
        if gap:
            raise TrajectoryError(gap)
        return self.motion.take(self.names[a], move, now, poses)

    def hold(self, a: int, q: np.ndarray) -> None:
        """Drop arm ``a``'s trajectories (running and next): it holds ``q`` ``(3,)`` at rest."""
        self.motion[self.names[a]].hold(q)
        self.ref_q[a] = q
        self.ref_qd[a] = 0.0
        self.ref_qdd[a] = 0.0

    def active(self, a: int, now: float) -> bool:
        """Return True while arm ``a`` has a trajectory to run (also before its start)."""
        return self.motion[self.names[a]].active(now)

    def reference(self, a: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return arm ``a``'s reference ``(q, qd, qdd)`` as of the last tick (copies)."""
        return self.ref_q[a].copy(), self.ref_qd[a].copy(), self.ref_qdd[a].copy()

    def reset(self, a: int, q: np.ndarray) -> None:
        """Start arm ``a`` afresh at ``q`` (teleported): no integral, no torque, holding."""
        self._pid.reset(a)
        self.tau[a] = 0.0
        self.hold(a, q)

    def brake(self, a: int, q: np.ndarray, qd: np.ndarray, now: float) -> None:
        """Stop arm ``a`` from ``(q, qd)`` ``(3,)`` each at its acceleration limits, then hold.

        Until the brake's first sample (now) the arm holds ``q``.
        """
        self.hold(a, q)
        self.motion[self.names[a]].brake(self.arms[a], q, qd, now, self.dt,
                                         ref_of=HermiteReference)

    def set_estop(self, on: bool, q: np.ndarray, qd: np.ndarray, now: float) -> None:
        """Set or clear the emergency stop; setting it brakes every arm from ``(q, qd)``.

        :param q, qd: ``(arms, 3)`` the measured joints now.
        """
        if on and not self.estop:
            for a in range(len(self.arms)):
                self.brake(a, q[a], qd[a], now)
        self.estop = bool(on)

    def check_recovery(self, a: int, path: np.ndarray, q: np.ndarray, qd: np.ndarray,
                       now: float) -> None:
        """Refuse a move of arm ``a`` under the emergency stop unless it only parts the arms.

        One separating move at a time: every other arm must stand still (no trajectory, no
        joint faster than 1e-3), and the move from ``q[a]`` through ``path`` ``(N, 3)`` must
        take arm ``a`` away from each of them (:func:`scara_collab.core.safety.separating`).

        :raises TrajectoryError: with the reason, if it does not.
        """
        others = [b for b in range(len(self.arms)) if b != a]
        if any(self.active(b, now) or np.any(np.abs(qd[b]) > 1e-3) for b in others):
            raise TrajectoryError('emergency stop is active and the other arm is moving: '
                                  'refused (one separating move at a time)')
        full = np.vstack([q[a], path])
        if not all(safety.separating(self.arms[a], full, self.arms[b], q[b]) for b in others):
            raise TrajectoryError('emergency stop is active: only a move that takes the arm '
                                  'away from the other one is run')


_REST = np.zeros(3)


def _holding(tau: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return an arm at rest: no velocity to keep within its limits, whatever its factor."""
    return _REST, _REST, _REST
