"""The simulated cell: both arms, the belt, the bins and the items in PyBullet, no ROS.

:class:`CellSim` owns its own PyBullet client (``pybullet_utils.bullet_client.BulletClient``,
never the global client). It loads the cell URDF of :func:`scara_collab.core.model.load_cell`
(``useFixedBase``, inertias from the file), steps physics at ``physics_rate`` and is the clock
(:attr:`CellSim.time`). The bridge node wraps it in ROS topics and services.

Physics step (every ``1 / physics_rate`` s of sim time):

1. read the six joints in one ``getJointStates`` call;
2. every ``physics_rate / servo_rate`` steps, the servo: sample each arm's reference (hold or
   cubic Hermite trajectory, :mod:`scara_collab.sim.reference`) and evaluate the control law
   for both arms at once (:mod:`scara_collab.sim.controllers`: PID on torque, or computed
   torque with one vectorised inverse-dynamics call), clamped to the effort limits. The torque
   is held until the next servo tick;
3. apply ``torque - friction(qd)`` with ``TORQUE_CONTROL``: the model's viscous + Coulomb
   friction (Coulomb smoothed by tanh) is applied here, explicitly, every step. PyBullet's
   own joint damping, link damping and velocity motors are switched off so friction is
   counted once;
4. ``stepSimulation``;
5. every ``physics_rate / item_rate`` steps, the items: the automatic feed, belt carrying and
   the events (see below).

Items are 0.1 m cubes (maximal-coordinate rigid bodies, cheap to simulate). The belt is a
frictionless static box with the URDF conveyor's geometry (the URDF link keeps its visual and
loses its collision): an item on it keeps its velocity exactly, and the item tick re-imposes
the belt velocity ``(speed, 0, 0)`` on every item resting on the belt (after a push, a
release onto the belt, a collision). Events, checked at the item tick: ``missed`` (an item on
the belt passes ``x_end``, removed), ``sorted`` / ``wrong_bin`` (an item at rest inside a bin,
removed; the event names the bin's robot), ``dropped`` (at rest on the floor, removed), plus
``spawned``, ``grasped``, ``released`` as they happen.

Example::

    >>> with CellSim() as sim:                 # defaults from config/ and the model
    ...     item = sim.spawn_item('red', y=0.1)
    ...     sim.step(1000)                     # 1 s of sim time
    ...     names, q, qd, effort = sim.joint_state()
    ...     round(sim.time, 6), names[0], sim.items()[0].state
    (1.0, 'scara_left_joint_1', 'belt')
"""
from contextlib import contextmanager
from dataclasses import dataclass
import math
import os
import sys
import tempfile
from typing import List, NamedTuple, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike
import pybullet
from pybullet_utils.bullet_client import BulletClient

from scara_collab.core import safety
from scara_collab.core.config import ConfigError, load_config
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.sorting import at_belt_height
from scara_collab.sim.controllers import (
    ComputedTorqueController, joint_gains, PidController, smooth_friction)
from scara_collab.sim.reference import HermiteReference, TrajectoryError, validate_trajectory

CONTROL_MODES = ('pid', 'computed_torque')
FEED_PATTERNS = ('random', 'mirror_pairs')
EVENT_KINDS = ('spawned', 'grasped', 'released', 'sorted', 'wrong_bin', 'missed', 'dropped')
PAYLOAD_CLASS = 'payload'
"""Class of the bodies :meth:`CellSim.attach_payload` creates (not a sortable item)."""

_COLOURS = {'red': (0.85, 0.15, 0.15, 1.0), 'blue': (0.15, 0.35, 0.9, 1.0),
            'green': (0.15, 0.7, 0.25, 1.0), 'yellow': (0.95, 0.8, 0.1, 1.0),
            PAYLOAD_CLASS: (0.5, 0.5, 0.5, 1.0)}
_PALETTE = ((0.85, 0.15, 0.15, 1.0), (0.15, 0.35, 0.9, 1.0), (0.15, 0.7, 0.25, 1.0))
_LOST_Z = -1.0          # m, an item below this fell through something: dropped
_CONSTRAINT_FORCE = 1e5  # N, the gripper's fixed constraint never slips


class JointStateSample(NamedTuple):
    """All six joints, left (j1, j2, quill) then right.

    :ivar names: joint names; :ivar position: ``(6,)`` rad | m; :ivar velocity: ``(6,)``;
    :ivar effort: ``(6,)`` motor torques / forces applied (after the effort clamp; the
        friction the joints feel is not included), N m | N.
    """

    names: Tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


@dataclass(frozen=True)
class Item:
    """One item as :meth:`CellSim.items` reports it.

    :ivar id: item id (unique over the run); :ivar cls: item class;
    :ivar position: ``(3,)`` centre in world, m; :ivar velocity: ``(3,)`` m/s;
    :ivar state: ``'belt'`` (resting on the belt, carried), ``'held'`` (in a gripper) or
        ``'free'`` (anything else: falling, in a bin, on the floor).
    """

    id: int
    cls: str
    position: np.ndarray
    velocity: np.ndarray
    state: str


@dataclass(frozen=True)
class SimEvent:
    """Something that happened to an item.

    :ivar time: sim time, s; :ivar kind: one of :data:`EVENT_KINDS`; :ivar item: item id;
    :ivar cls: item class; :ivar robot: the arm involved (gripper, bin, last holder of a
        dropped item) or ``''``; :ivar cause: for an item that left the belt without a
        grasp (``dropped``, ``missed`` after a push), what touched it last, else ``''``.
    """

    time: float
    kind: str
    item: int
    cls: str
    robot: str = ''
    cause: str = ''


class _ItemRec:
    """Mutable bookkeeping of one item (internal)."""

    __slots__ = ('id', 'body', 'cls', 'mass', 'state', 'holder', 'constraint', 'last_robot',
                 'cause')

    def __init__(self, item_id: int, body: int, cls: str, mass: float, state: str):
        self.id, self.body, self.cls, self.mass, self.state = item_id, body, cls, mass, state
        self.holder: Optional[int] = None
        self.constraint: Optional[int] = None
        self.last_robot = ''
        self.cause = ''  # what knocked it off the belt (it was never grasped)


@contextmanager
def _quiet_stdout():
    """Silence PyBullet's C-level prints (URDF importer warnings) for a moment."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):
        yield
        return
    try:
        with open(os.devnull, 'w') as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _divisor(physics_rate: float, rate: float, key: str) -> int:
    """Return the physics steps per tick of a loop running at ``rate`` (must be an integer)."""
    ratio = physics_rate / rate
    n = int(round(ratio))
    if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
        raise ConfigError(f'simulation.yaml: {key} ({rate} Hz) must divide physics_rate '
                          f'({physics_rate} Hz) and not exceed it')
    return n


class CellSim:
    """The PyBullet cell (see the module docstring for the loop, the belt and the events).

    :param cell: the cell model; default :func:`~scara_collab.core.model.load_cell`.
    :param sim_cfg: ``simulation.yaml`` parameters; default: the package's file.
    :param ctl_cfg: ``controllers.yaml`` parameters; default: the package's file.
    :param gui: open the PyBullet GUI instead of running headless (DIRECT).
    :param control_mode: ``'pid'`` or ``'computed_torque'``; default ``ctl_cfg['control_mode']``.
    :param seed: item RNG seed; default ``sim_cfg['item_seed']``.
    :raises ConfigError: for settings that do not fit together (rates, jitter vs belt width).
    """

    def __init__(self, cell: Optional[CellModel] = None, sim_cfg: Optional[dict] = None,
                 ctl_cfg: Optional[dict] = None, gui: bool = False,
                 control_mode: Optional[str] = None, seed: Optional[int] = None):
        """Check the settings, make the controllers and build the PyBullet scene."""
        self.cell = cell if cell is not None else load_cell()
        self.sim_cfg = sim_cfg if sim_cfg is not None else load_config('simulation')
        self.ctl_cfg = ctl_cfg if ctl_cfg is not None else load_config('controllers')
        cfg = self.sim_cfg
        self.control_mode = control_mode or self.ctl_cfg['control_mode']
        if self.control_mode not in CONTROL_MODES:
            raise ValueError(f'control_mode must be one of {CONTROL_MODES}, '
                             f'got {self.control_mode!r}')
        self.physics_rate = float(cfg['physics_rate'])
        self.dt = 1.0 / self.physics_rate
        self._servo_every = _divisor(self.physics_rate, float(cfg['servo_rate']), 'servo_rate')
        self._item_every = _divisor(self.physics_rate, float(cfg['item_rate']), 'item_rate')
        self._servo_dt = self._servo_every * self.dt
        belt, size = self.cell.belt, self.cell.item_size
        self._half_free = belt.width / 2.0 - size / 2.0
        if float(cfg['lateral_jitter']) > self._half_free + 1e-9:
            raise ConfigError(f'simulation.yaml: lateral_jitter {cfg["lateral_jitter"]} m puts '
                              f'items off the {belt.width} m belt (at most {self._half_free} m)')
        self._rng = np.random.default_rng(int(cfg['item_seed'] if seed is None else seed))
        self.arms = self.cell.arms
        self.robots = tuple(a.name for a in self.arms)
        self.joint_names = tuple(n for a in self.arms for n in a.joint_names)
        self._gravity = [float(v) for v in cfg['gravity']]
        self._eps = float(cfg['friction_smoothing'])
        self._effort = np.stack([a.max_effort for a in self.arms])
        self._viscous = np.stack([a.viscous for a in self.arms])
        self._coulomb = np.stack([a.coulomb for a in self.arms])
        pid = self.ctl_cfg['pid']
        self._pid = PidController(joint_gains(pid, 'kp'), joint_gains(pid, 'ki'),
                                  joint_gains(pid, 'kd'), self._effort, len(self.arms))
        self._ct = ComputedTorqueController(
            self.arms, joint_gains(self.ctl_cfg['computed_torque'], 'kp'),
            joint_gains(self.ctl_cfg['computed_torque'], 'kd'), g=-self._gravity[2],
            friction_smoothing=self._eps)
        self._pb: Optional[BulletClient] = None
        try:
            self._build(gui)
        except Exception:
            self.close()
            raise

    # --- construction ---------------------------------------------------------------------
    def _build(self, gui: bool) -> None:
        with _quiet_stdout():
            self._pb = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        pb = self._pb
        pb.setTimeStep(self.dt)
        pb.setPhysicsEngineParameter(numSolverIterations=int(self.sim_cfg['solver_iterations']))
        pb.setGravity(*self._gravity)
        fd, path = tempfile.mkstemp(suffix='.urdf', prefix='scara_cell_')
        try:
            with os.fdopen(fd, 'w') as f:
                f.write(self.cell.urdf)
            with _quiet_stdout():
                self._body = pb.loadURDF(path, useFixedBase=True,
                                         flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        finally:
            os.unlink(path)
        body = self._body
        joints = {}
        links = {}
        for j in range(pb.getNumJoints(body)):
            info = pb.getJointInfo(body, j)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        missing = [n for n in self.joint_names if n not in joints]
        if missing:
            raise ConfigError(f'the cell URDF has no joints {missing}')
        self._jidx = [joints[n] for n in self.joint_names]
        self._link_names = {idx: name for name, idx in links.items()}
        self._quill = [links[f'{a.name}_quill'] for a in self.arms]
        pb.setJointMotorControlArray(body, self._jidx, pybullet.VELOCITY_CONTROL,
                                     forces=[0.0] * len(self._jidx))
        pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0)
        for j in self._jidx:
            pb.changeDynamics(body, j, jointDamping=0.0, linearDamping=0.0, angularDamping=0.0)
        self._build_belt(links['conveyor'])
        floor = pb.createCollisionShape(pybullet.GEOM_PLANE)
        self._floor = pb.createMultiBody(0.0, floor, -1, [0.0, 0.0, 0.0])
        size = self.cell.item_size
        self._item_shape = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3)
        self._item_visual = {}
        bsize = self.cell.config['bins']['size']
        self._bins = [(robot, cls, float(p[0]), float(p[1]), float(p[2]), bsize[0] / 2.0,
                       bsize[1] / 2.0, float(p[2]) + bsize[2] + size)
                      for (robot, cls), p in self.cell.bins.items()]
        if gui:
            pb.resetDebugVisualizerCamera(6.0, 30.0, -40.0,
                                          [float(self.arms[0].base[0, 3]), 0.0, 0.3])
        # bound calls for the hot loop (BulletClient builds a partial on every attribute access)
        self._get_states = pb.getJointStates
        self._set_motors = pb.setJointMotorControlArray
        self._step_sim = pb.stepSimulation
        self._get_pose = pb.getBasePositionAndOrientation
        self._get_vel = pb.getBaseVelocity
        self._set_vel = pb.resetBaseVelocity
        # state
        self._steps = 0
        self._estop = False
        self._items = {}
        self._next_id = 1
        self._events: List[SimEvent] = []
        self._held: List[Optional[int]] = [None] * len(self.arms)
        self._payload = np.zeros(len(self.arms))
        self._traj: List[Optional[HermiteReference]] = [None] * len(self.arms)
        self._tau = np.zeros((len(self.arms), 3))
        q, _ = self._read()
        self._ref_q = q.copy()
        self._ref_qd = np.zeros_like(q)
        self._ref_qdd = np.zeros_like(q)
        self.set_feed(float(self.sim_cfg['feed_interval']), self.sim_cfg['feed_pattern'])

    def _build_belt(self, link: int) -> None:
        """Replace the URDF conveyor's collision by a static, frictionless rigid box."""
        pb = self._pb
        shape = pb.getCollisionShapeData(self._body, link)[0]
        half = [float(v) / 2.0 for v in shape[3]]
        state = pb.getLinkState(self._body, link, computeForwardKinematics=True)
        pos, orn = pb.multiplyTransforms(state[0], state[1], shape[5], shape[6])
        pb.setCollisionFilterGroupMask(self._body, link, 0, 0)
        box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        self._belt = pb.createMultiBody(0.0, box, -1, pos, orn, useMaximalCoordinates=True)
        pb.changeDynamics(self._belt, -1, lateralFriction=0.0, rollingFriction=0.0,
                          spinningFriction=0.0)

    # --- clock and stepping ---------------------------------------------------------------
    @property
    def time(self) -> float:
        """Sim time, s (physics steps taken times the step)."""
        return self._steps * self.dt

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps (servo, friction, items included)."""
        body, idx = self._body, self._jidx
        get_states, set_motors, step_sim = self._get_states, self._set_motors, self._step_sim
        torque = pybullet.TORQUE_CONTROL
        shape = self._tau.shape
        for _ in range(int(n)):
            states = get_states(body, idx)
            qd = np.array([s[1] for s in states]).reshape(shape)
            if self._steps % self._servo_every == 0:
                self._servo(np.array([s[0] for s in states]).reshape(shape), qd)
            force = self._tau - smooth_friction(self._viscous, self._coulomb, qd, self._eps)
            set_motors(body, idx, torque, forces=force.ravel().tolist())
            step_sim()
            self._steps += 1
            if self._steps % self._item_every == 0:
                self._update_items()

    def _servo(self, q: np.ndarray, qd: np.ndarray) -> None:
        now = self._steps * self.dt
        for a, ref in enumerate(self._traj):
            if ref is None or now < ref.start:
                continue
            self._ref_q[a], self._ref_qd[a], self._ref_qdd[a] = ref.sample(now)
            if now >= ref.end:
                self._traj[a] = None  # done: hold the last point (sample() gave it at rest)
        if self.control_mode == 'pid':
            tau = self._pid(q, qd, self._ref_q, self._ref_qd, self._servo_dt)
        else:
            tau = self._ct(q, qd, self._ref_q, self._ref_qd, self._ref_qdd, self._payload)
        self._tau = np.minimum(np.maximum(tau, -self._effort), self._effort)

    def _read(self) -> Tuple[np.ndarray, np.ndarray]:
        states = self._get_states(self._body, self._jidx)
        q = np.array([s[0] for s in states]).reshape(-1, 3)
        qd = np.array([s[1] for s in states]).reshape(-1, 3)
        return q, qd

    # --- arms -----------------------------------------------------------------------------
    def _index(self, robot: str) -> int:
        try:
            return self.robots.index(robot)
        except ValueError:
            raise TrajectoryError(f'unknown robot {robot!r}; the cell has {list(self.robots)}')\
                from None

    def joint_state(self) -> JointStateSample:
        """Positions, velocities and applied motor efforts of all six joints (see the type)."""
        q, qd = self._read()
        return JointStateSample(self.joint_names, q.ravel(), qd.ravel(), self._tau.ravel().copy())

    def arm_state(self, robot: str) -> Tuple[np.ndarray, np.ndarray]:
        """Measured ``(q, qd)`` of one arm, each ``(3,)``."""
        a = self._index(robot)
        q, qd = self._read()
        return q[a], qd[a]

    def reference(self, robot: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the servo's reference ``(q, qd, qdd)`` of one arm (as of the last tick)."""
        a = self._index(robot)
        return self._ref_q[a].copy(), self._ref_qd[a].copy(), self._ref_qdd[a].copy()

    def tool_tip(self, robot: str) -> np.ndarray:
        """World position of the tool tip (the ``<robot>_quill`` link frame origin), ``(3,)``."""
        a = self._index(robot)
        state = self._pb.getLinkState(self._body, self._quill[a], computeForwardKinematics=True)
        return np.array(state[4])

    def _hold_arm(self, a: int) -> None:
        q, _ = self._read()
        self._traj[a] = None
        self._ref_q[a] = q[a]
        self._ref_qd[a] = 0.0
        self._ref_qdd[a] = 0.0

    def execute(self, robot: str, t: ArrayLike, q: ArrayLike, qd: Optional[ArrayLike] = None,
                qdd: Optional[ArrayLike] = None) -> None:
        """Run a joint trajectory on one arm, replacing the running one.

        Before ``t[0]`` the arm holds the position it has now; between points the reference
        is the cubic Hermite spline of positions and velocities (velocities by central finite
        differences, zero at both ends, if not given; accelerations its derivative unless
        given); after ``t[-1]`` it holds the last point.

        :param robot: arm name, e.g. ``scara_left``.
        :param t: ``(N,)`` absolute sim times, s, strictly increasing.
        :param q: ``(N, 3)`` joint positions; :param qd, qdd: ``(N, 3)`` or ``None``.
        While the emergency stop is set, only a move that takes this arm away from the other
        one, standing still, is run (:func:`scara_collab.core.safety.separating`): the way
        to part arms that stopped too close.

        :raises TrajectoryError: (a ``ValueError``) with the reason: unknown robot, emergency
            stop active and the move not separating, bad shape, non-finite value,
            non-increasing times, a position outside the joint limits, a velocity above the
            limits (also between points), or a start more than ``start_tolerance`` away from
            the measured position. The arm keeps doing what it did.
        """
        a = self._index(robot)
        arm = self.arms[a]
        t, q, qd, qdd = validate_trajectory(
            t, q, qd, arm.lower, arm.upper, arm.max_velocity,
            float(self.sim_cfg['velocity_tolerance']), qdd=qdd)
        if self._estop:
            self._check_recovery(a, q)
        ref = HermiteReference(t, q, qd, qdd)
        q_now = self._read()[0][a]
        start_q = ref.sample(max(self.time, ref.start))[0]
        jump = np.abs(start_q - q_now)
        tol = float(self.sim_cfg['start_tolerance'])
        if np.any(jump > tol):
            j = int(np.argmax(jump))
            raise TrajectoryError(
                f'the trajectory starts {jump[j]:.4f} away from the measured position of joint '
                f'{j + 1} ({q_now[j]:.4f}); at most {tol} is allowed')
        self._hold_arm(a)
        self._traj[a] = ref

    def hold(self, robot: str) -> None:
        """Drop the running trajectory and hold the arm where it is now."""
        self._hold_arm(self._index(robot))

    def active(self, robot: str) -> bool:
        """Return ``True`` while the arm has a trajectory to run (also before its start time)."""
        ref = self._traj[self._index(robot)]
        return ref is not None and self.time < ref.end

    def _check_recovery(self, a: int, q: np.ndarray) -> None:
        """Refuse a move under the emergency stop unless it only parts the arms."""
        q_now, qd_now = self._read()
        others = [b for b in range(len(self.arms)) if b != a]
        if any(self.active(self.robots[b]) or np.any(np.abs(qd_now[b]) > 1e-3)
               for b in others):
            raise TrajectoryError('emergency stop is active and the other arm is moving: '
                                  'refused (one separating move at a time)')
        path = np.vstack([q_now[a], q])
        if not all(safety.separating(self.arms[a], path, self.arms[b], q_now[b])
                   for b in others):
            raise TrajectoryError('emergency stop is active: only a move that takes the arm '
                                  'away from the other one is run')

    def set_estop(self, on: bool) -> None:
        """Emergency stop: both arms brake at their acceleration limits and then hold.

        While it is set, new trajectories are refused unless they part the arms (see
        :meth:`execute`).
        """
        if on and not self._estop:
            for robot in self.robots:
                self.brake(robot)
        self._estop = bool(on)

    def brake(self, robot: str) -> None:
        """Drop the running trajectory: brake every joint at its acceleration limit, then hold.

        The stop of :func:`scara_collab.core.safety.braking` from the measured state.
        """
        a = self._index(robot)
        q, qd = self._read()
        t, pos, vel, acc = safety.braking(self.arms[a], q[a], qd[a], self._servo_dt)
        self._hold_arm(a)
        self._traj[a] = HermiteReference(self.time + t, pos, vel, acc)

    @property
    def estop(self) -> bool:
        """``True`` while the emergency stop is set."""
        return self._estop

    def reset_arm(self, robot: str, q: ArrayLike, qd: Optional[ArrayLike] = None) -> None:
        """Teleport an arm to ``q`` ``(3,)`` and hold that position (tests, benchmarks).

        :param qd: ``(3,)`` joint velocities to start with (default at rest).
        :raises TrajectoryError: for an unknown robot, a bad or out-of-limit ``q``, or while
            the gripper holds an item.
        """
        a = self._index(robot)
        arm = self.arms[a]
        _, q, qd, _ = validate_trajectory([self.time], [q], None if qd is None else [qd],
                                          arm.lower, arm.upper, arm.max_velocity)
        if self._held[a] is not None:
            raise TrajectoryError(f'{robot} holds item {self._held[a]}: release it first')
        for j, idx in enumerate(self._jidx[3 * a:3 * a + 3]):
            self._pb.resetJointState(self._body, idx, float(q[0, j]), float(qd[0, j]))
        self._pid.reset(a)
        self._tau[a] = 0.0
        self._hold_arm(a)

    def mass_matrix(self, robot: str, q: ArrayLike) -> np.ndarray:
        """Return PyBullet's joint-space inertia matrix ``(3, 3)`` of one arm at ``q`` ``(3,)``.

        ``calculateMassMatrix`` takes the positions of every movable joint of the cell body;
        the other arm is left at its current state (the arms are independent chains, so the
        matrix is block diagonal) and this arm's block is returned.
        """
        a = self._index(robot)
        q_all = self._read()[0].copy()
        q_all[a] = np.asarray(q, dtype=float)
        m = np.array(self._pb.calculateMassMatrix(self._body, q_all.ravel().tolist()))
        return m[3 * a:3 * a + 3, 3 * a:3 * a + 3]

    # --- items ----------------------------------------------------------------------------
    def set_feed(self, interval: Optional[float] = None, pattern: Optional[str] = None) -> None:
        """Change the automatic feed; the next item comes one ``interval`` from now.

        :param interval: s of sim time between feeds, ``0`` = no automatic feed.
        :param pattern: ``'random'`` (one item, random class and lateral offset) or
            ``'mirror_pairs'`` (two items of one class at ``y`` and ``-y`` about the belt
            centre line, same ``x``).
        :raises ValueError: for a negative or non-finite interval or an unknown pattern.
        """
        if interval is not None:
            if not (math.isfinite(interval) and interval >= 0):
                raise ValueError(f'feed interval must be a number >= 0, got {interval!r}')
            self.feed_interval = float(interval)
        if pattern is not None:
            if pattern not in FEED_PATTERNS:
                raise ValueError(f'feed pattern must be one of {FEED_PATTERNS}, got {pattern!r}')
            self.feed_pattern = pattern
        self._next_feed = self.time + self.feed_period

    @property
    def feed_period(self) -> float:
        """Return the seconds between feeds.

        ``feed_interval`` is per item, so mirror pairs (two items) come every two intervals
        and every pattern delivers the same items per minute.
        """
        return self.feed_interval * (2.0 if self.feed_pattern == 'mirror_pairs' else 1.0)

    def _colour(self, cls: str):
        if cls in _COLOURS:
            return _COLOURS[cls]
        classes = list(self.cell.item_classes)
        return _PALETTE[classes.index(cls) % len(_PALETTE)] if cls in classes else (1, 1, 1, 1)

    def _create_item(self, cls: str, pos, mass: float, state: str,
                     size: Optional[float] = None) -> _ItemRec:
        pb = self._pb
        if size is None:
            shape = self._item_shape
            if cls not in self._item_visual:
                self._item_visual[cls] = pb.createVisualShape(
                    pybullet.GEOM_BOX, halfExtents=[self.cell.item_size / 2] * 3,
                    rgbaColor=self._colour(cls))
            visual = self._item_visual[cls]
        else:
            shape = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3)
            visual = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3,
                                          rgbaColor=self._colour(cls))
        body = pb.createMultiBody(mass, shape, visual, [float(v) for v in pos],
                                  useMaximalCoordinates=True)
        pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0)
        rec = _ItemRec(self._next_id, body, cls, mass, state)
        self._next_id += 1
        self._items[rec.id] = rec
        return rec

    def spawn_item(self, cls: Optional[str] = None, y: Optional[float] = None,
                   x: Optional[float] = None) -> int:
        """Put an item on the belt, moving at belt speed; return its id.

        :param cls: item class; default: random (seeded).
        :param y: lateral position (world); default: belt centre + uniform jitter.
        :param x: position along the belt; default: the inlet, ``x_start + inlet_margin``.
        :raises ValueError: unknown class, or a position off the belt.
        """
        belt = self.cell.belt
        classes = self.cell.item_classes
        if cls is None:
            cls = classes[int(self._rng.integers(len(classes)))]
        if cls not in classes:
            raise ValueError(f'unknown item class {cls!r}; the cell sorts {list(classes)}')
        jitter = float(self.sim_cfg['lateral_jitter'])
        y = belt.centre_y + self._rng.uniform(-jitter, jitter) if y is None else float(y)
        x = belt.x_start + float(self.sim_cfg['inlet_margin']) if x is None else float(x)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f'item position must be finite, got x={x}, y={y}')
        if abs(y - belt.centre_y) > self._half_free + 1e-9:
            raise ValueError(f'y={y:.3f} puts the item off the belt (|y - {belt.centre_y}| '
                             f'<= {self._half_free:.3f})')
        if not belt.x_start <= x < belt.x_end:
            raise ValueError(f'x={x:.3f} is not on the belt [{belt.x_start}, {belt.x_end})')
        z = belt.top_z + self.cell.item_size / 2.0
        rec = self._create_item(cls, (x, y, z), self.cell.item_mass, 'belt')
        self._set_vel(rec.body, [belt.speed, 0.0, 0.0], [0.0, 0.0, 0.0])
        self._events.append(SimEvent(self.time, 'spawned', rec.id, cls))
        return rec.id

    def _feed(self) -> None:
        if self.feed_pattern == 'random':
            self.spawn_item()
            return
        classes = self.cell.item_classes
        cls = classes[int(self._rng.integers(len(classes)))]
        size = self.cell.item_size
        off = self._rng.uniform(size, max(size, float(self.sim_cfg['lateral_jitter'])))
        cy = self.cell.belt.centre_y
        self.spawn_item(cls, cy + off)
        self.spawn_item(cls, cy - off)

    def _remove(self, rec: _ItemRec, kind: str, robot: str = '') -> None:
        if rec.constraint is not None:
            self._pb.removeConstraint(rec.constraint)
        self._pb.removeBody(rec.body)
        del self._items[rec.id]
        cause = rec.cause if kind in ('dropped', 'missed') else ''
        self._events.append(SimEvent(self.time, kind, rec.id, rec.cls, robot, cause))

    def _update_items(self) -> None:
        """Feed, carry items on the belt, detect missed / sorted / wrong_bin / dropped."""
        if self.feed_interval > 0 and self.time >= self._next_feed - 1e-9:
            self._next_feed += self.feed_period
            self._feed()
        belt = self.cell.belt
        half_w = belt.width / 2.0
        carry = [belt.speed, 0.0, 0.0]
        zero = [0.0, 0.0, 0.0]
        rest_speed_sq = float(self.sim_cfg['rest_speed']) ** 2
        for rec in list(self._items.values()):
            if rec.state == 'held':
                continue
            x, y, z = self._get_pose(rec.body)[0]
            if x > belt.x_end and rec.state == 'belt':  # carried off the end (maybe tipping)
                self._remove(rec, 'missed')
                continue
            if (at_belt_height(self.cell, z) and abs(y - belt.centre_y) <= half_w
                    and belt.x_start <= x <= belt.x_end):
                rec.state = 'belt'
                self._set_vel(rec.body, carry, zero)
                continue
            if rec.state == 'belt' and not rec.cause:  # it left the belt without a grasp
                rec.cause = self._touching(rec)
            rec.state = 'free'
            if z < _LOST_Z:
                self._remove(rec, 'dropped', rec.last_robot)
                continue
            v = self._get_vel(rec.body)[0]
            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > rest_speed_sq:
                continue
            for robot, cls, bx, by, _, hx, hy, top in self._bins:
                if abs(x - bx) < hx and abs(y - by) < hy and z < top:
                    self._remove(rec, 'sorted' if cls == rec.cls else 'wrong_bin', robot)
                    break
            else:
                if z < self.cell.item_size:
                    self._remove(rec, 'dropped', rec.last_robot)

    def _touching(self, rec: _ItemRec) -> str:
        """Name what touches an item now: an arm link, another item, or nothing."""
        others = {r.body: r for r in self._items.values() if r is not rec}
        found = ''
        for c in self._pb.getContactPoints(bodyA=rec.body):
            if c[2] == self._body:
                return f'knocked by {self._link_names.get(c[4], "the cell")}'
            if c[2] in others and not found:
                other = others[c[2]]
                found = f'pushed by item {other.id}' + (
                    f' (held by {self.robots[other.holder]})' if other.holder is not None
                    else '')
        return found or 'left the belt with nothing touching it'

    def items(self) -> List[Item]:
        """Every item in the cell now (positions and velocities read from PyBullet)."""
        out = []
        for rec in self._items.values():
            pos = self._get_pose(rec.body)[0]
            vel = self._get_vel(rec.body)[0]
            out.append(Item(rec.id, rec.cls, np.array(pos), np.array(vel), rec.state))
        return out

    def pop_events(self) -> List[SimEvent]:
        """Events since the last call, oldest first (the list is emptied)."""
        events, self._events = self._events, []
        return events

    # --- gripper --------------------------------------------------------------------------
    def held_item(self, robot: str) -> Optional[int]:
        """Id of the item in the gripper of ``robot``, or ``None``."""
        return self._held[self._index(robot)]

    def _attach(self, a: int, rec: _ItemRec) -> None:
        pb = self._pb
        link = pb.getLinkState(self._body, self._quill[a], computeForwardKinematics=True)
        inv_pos, inv_orn = pb.invertTransform(link[0], link[1])
        pos, orn = self._get_pose(rec.body)
        rel_pos, rel_orn = pb.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        cid = pb.createConstraint(self._body, self._quill[a], rec.body, -1, pybullet.JOINT_FIXED,
                                  [0.0, 0.0, 0.0], rel_pos, [0.0, 0.0, 0.0], rel_orn,
                                  [0.0, 0.0, 0.0, 1.0])
        pb.changeConstraint(cid, maxForce=_CONSTRAINT_FORCE)
        pb.setCollisionFilterPair(self._body, rec.body, self._quill[a], -1, 0)
        rec.constraint, rec.holder, rec.state = cid, a, 'held'
        rec.last_robot = self.robots[a]
        self._held[a] = rec.id
        self._payload[a] = rec.mass

    def grasp(self, robot: str) -> Tuple[bool, str]:
        """Attach the nearest item whose top centre is within ``grasp_tolerance`` of the tip.

        The item is held by a fixed constraint at its current pose relative to the quill, so
        the arm feels its mass; the computed-torque feed-forward adds it as payload.

        :return: ``(True, message)``, or ``(False, reason)`` if the gripper already holds an
            item or nothing is in reach.
        """
        try:
            a = self._index(robot)
        except TrajectoryError as exc:
            return False, str(exc)
        if self._held[a] is not None:
            return False, f'{robot} already holds item {self._held[a]}'
        tip = self.tool_tip(robot)
        half = self.cell.item_size / 2.0
        tol = float(self.sim_cfg['grasp_tolerance'])
        best, best_d = None, math.inf
        for rec in self._items.values():
            if rec.state == 'held':
                continue
            x, y, z = self._get_pose(rec.body)[0]
            d = math.dist((x, y, z + half), tip)
            if d < best_d:
                best, best_d = rec, d
        if best is None or best_d > tol:
            near = '' if best is None else f'; the nearest item top is {best_d:.3f} m away'
            return False, f'nothing to grasp within {tol} m of the {robot} tool tip{near}'
        self._attach(a, best)
        self._events.append(SimEvent(self.time, 'grasped', best.id, best.cls, robot))
        return True, f'{robot} grasped item {best.id} ({best.cls}) at {best_d * 1000:.1f} mm'

    def release(self, robot: str) -> Tuple[bool, str]:
        """Open the gripper: the held item falls free.

        :return: ``(True, message)``, or ``(False, reason)`` if the gripper holds nothing.
        """
        try:
            a = self._index(robot)
        except TrajectoryError as exc:
            return False, str(exc)
        item_id = self._held[a]
        if item_id is None:
            return False, f'{robot} holds nothing to release'
        rec = self._items[item_id]
        self._pb.removeConstraint(rec.constraint)
        self._pb.setCollisionFilterPair(self._body, rec.body, self._quill[a], -1, 1)
        rec.constraint, rec.holder, rec.state = None, None, 'free'
        self._held[a] = None
        self._payload[a] = 0.0
        self._events.append(SimEvent(self.time, 'released', rec.id, rec.cls, robot))
        return True, f'{robot} released item {rec.id} ({rec.cls})'

    def attach_payload(self, robot: str, mass: float, size: Optional[float] = None) -> int:
        """Hang a test body of ``mass`` kg (a cube, class ``'payload'``) on the tool.

        Its top centre is placed at the tool tip and it is held like a grasped item, so the
        physics feels it and the computed-torque feed-forward knows it. For benchmarks.

        :param size: cube edge, m; default the item size.
        :return: the body's item id (``release`` drops it).
        :raises ValueError: for a mass or size <= 0, or a gripper that already holds something.
        """
        a = self._index(robot)
        size = self.cell.item_size if size is None else float(size)
        if not (math.isfinite(mass) and mass > 0 and math.isfinite(size) and size > 0):
            raise ValueError(f'payload mass and size must be > 0, got {mass!r} kg, {size!r} m')
        if self._held[a] is not None:
            raise ValueError(f'{robot} already holds item {self._held[a]}')
        tip = self.tool_tip(robot)
        rec = self._create_item(PAYLOAD_CLASS, tip - [0.0, 0.0, size / 2.0], float(mass),
                                'held', size)
        self._attach(a, rec)
        return rec.id

    # --- lifetime -------------------------------------------------------------------------
    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        if self._pb is not None:
            try:
                self._pb.disconnect()
            except pybullet.error:
                pass
            self._pb = None

    def __enter__(self) -> 'CellSim':
        """Return the simulator itself."""
        return self

    def __exit__(self, *exc) -> None:
        """Disconnect the PyBullet client."""
        self.close()
