"""The simulated cell: both arms, the belt, the bins and the items in PyBullet, no ROS.

:class:`CellSim` owns its own PyBullet client (``pybullet_utils.bullet_client.BulletClient``,
never the global client). It loads the cell URDF of :func:`scara_collab.core.model.load_cell`
(``useFixedBase``, inertias from the file), steps physics at ``physics_rate`` and is the clock
(:attr:`CellSim.time`). The bridge node wraps it in ROS topics and services.

Physics step (every ``1 / physics_rate`` s of sim time):

1. read the six joints in one ``getJointStates`` call;
2. every ``physics_rate / servo_rate`` steps, the servo (:class:`scara_collab.sim.servo.Servo`,
   which also owns the emergency stop): sample each arm's reference (hold or
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
   the events (:meth:`scara_collab.sim.conveyor.Conveyor.update`).

Items are 0.1 m cubes (maximal-coordinate rigid bodies, cheap to simulate) on the belt of a
:class:`~scara_collab.sim.conveyor.Conveyor` in the same PyBullet world (the feed, the items,
the bins and their events live there); the simulator adds the arms, their servo and the
grippers, which hold an item by a fixed constraint.

Example::

    >>> with CellSim() as sim:                 # defaults from config/ and the model
    ...     item = sim.conveyor.spawn_item('red', y=0.1)
    ...     sim.step(1000)                     # 1 s of sim time
    ...     names, q, qd, effort = sim.joint_state()
    ...     round(sim.time, 6), names[0], sim.conveyor.items()[0].state
    (1.0, 'scara_left_joint_1', 'belt')
"""
from contextlib import contextmanager
import os
import sys
import tempfile
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple
from xml.etree import ElementTree

import numpy as np
from numpy.typing import ArrayLike
import pybullet
from pybullet_utils.bullet_client import BulletClient

from scara_collab.core.config import ConfigError, load_config
from scara_collab.core.frames import quaternion, Tree
from scara_collab.core.model import CellModel, load_cell, parse_urdf
from scara_collab.sim.controllers import applied_efforts
from scara_collab.sim.conveyor import BeltBox, Conveyor
from scara_collab.sim.gripper import Grippers
from scara_collab.sim.reference import robot_index, TrajectoryError, validate_trajectory
from scara_collab.sim.servo import CONTROL_MODES, Servo

__all__ = ['CellSim', 'CONTROL_MODES', 'JointStateSample']


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


class World(NamedTuple):
    """The cell URDF loaded into a PyBullet world (see :func:`load_world`).

    :ivar body: the cell's multibody; :ivar joints: the arms' joint indices, in
        ``joint_names`` order; :ivar link_names: link name by index (the arms' moving links;
        the fixed ones are merged into the base, index -1); :ivar quills: each arm's quill
        link (the tool); :ivar belt: the conveyor's collision box, left out of the body.
    """

    body: int
    joints: List[int]
    link_names: Dict[int, str]
    quills: List[int]
    belt: BeltBox


def _without_belt(cell: CellModel) -> Tuple[str, BeltBox]:
    """Return the cell URDF without the conveyor link's collision, and that collision box.

    The belt is simulated as a separate frictionless box (:class:`Conveyor`), so the URDF's
    own belt collision is taken out before loading rather than filtered out after.
    """
    link = parse_urdf(cell.urdf).link_map['conveyor']
    if len(link.collisions) != 1 or link.collisions[0].geometry.box is None:
        raise ConfigError("the cell URDF's conveyor link must have one box collision")
    col = link.collisions[0]
    origin = np.eye(4) if col.origin is None else np.asarray(col.origin, dtype=float)
    pose = Tree.of(cell.urdf).pose('conveyor', {}) @ origin
    box = BeltBox(tuple(pose[:3, 3].tolist()), quaternion(pose[:3, :3]),
                  tuple((np.asarray(col.geometry.box.size, dtype=float) / 2.0).tolist()))
    root = ElementTree.fromstring(cell.urdf)
    for node in root.iter('link'):
        if node.get('name') == 'conveyor':
            for collision in node.findall('collision'):
                node.remove(collision)
    return ElementTree.tostring(root, encoding='unicode'), box


def load_world(pb: BulletClient, cell: CellModel, joint_names: Sequence[str]) -> World:
    """Load the cell URDF (fixed base, inertias from the file) and a floor into ``pb``.

    The fixed links (the arms' bases, the conveyor, the bins) are merged into the base
    (``URDF_MERGE_FIXED_LINKS``): the multibody then has only the six moving links, and a
    physics step with no items costs about half as much (9 instead of 17 µs). The conveyor's
    collision is left out (:func:`_without_belt`). The arms' joints are set up for torque
    control with friction applied explicitly: the default velocity motors are switched off
    (zero force) and PyBullet's own joint and link damping are zeroed, so friction is counted
    once (:mod:`scara_collab.sim.cell_sim`).

    :raises ConfigError: if the URDF lacks one of ``joint_names``.
    """
    urdf, belt = _without_belt(cell)
    fd, path = tempfile.mkstemp(suffix='.urdf', prefix='scara_cell_')
    try:
        with os.fdopen(fd, 'w') as f:
            f.write(urdf)
        with _quiet_stdout():
            body = pb.loadURDF(path, useFixedBase=True,
                               flags=pybullet.URDF_USE_INERTIA_FROM_FILE
                               | pybullet.URDF_MERGE_FIXED_LINKS)
    finally:
        os.unlink(path)
    joints, links = {}, {}
    for j in range(pb.getNumJoints(body)):
        info = pb.getJointInfo(body, j)
        joints[info[1].decode()] = j
        links[info[12].decode()] = j
    missing = [n for n in joint_names if n not in joints]
    if missing:
        raise ConfigError(f'the cell URDF has no joints {missing}')
    idx = [joints[n] for n in joint_names]
    pb.setJointMotorControlArray(body, idx, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(idx))
    pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0)
    for j in idx:
        pb.changeDynamics(body, j, jointDamping=0.0, linearDamping=0.0, angularDamping=0.0)
    pb.createMultiBody(0.0, pb.createCollisionShape(pybullet.GEOM_PLANE), -1, [0.0, 0.0, 0.0])
    return World(body, idx, {i: name for name, i in links.items()},
                 [links[f'{a.name}_quill'] for a in cell.arms], belt)


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
        if self.control_mode not in CONTROL_MODES:  # before PyBullet starts
            raise ValueError(f'control_mode must be one of {CONTROL_MODES}, '
                             f'got {self.control_mode!r}')
        self.physics_rate = float(cfg['physics_rate'])
        self.dt = 1.0 / self.physics_rate
        self._servo_every = _divisor(self.physics_rate, float(cfg['servo_rate']), 'servo_rate')
        self._item_every = _divisor(self.physics_rate, float(cfg['item_rate']), 'item_rate')
        self._servo_dt = self._servo_every * self.dt
        self._seed = int(cfg['item_seed'] if seed is None else seed)
        allowance = float(self.ctl_cfg.get('admission_allowance', 0.0))
        #: m between the arms' commitments that an admitted trajectory keeps (0: no check)
        self.admission_margin = (self.cell.safety_margin + allowance if allowance >= 0
                                 else 0.0)
        self.arms = self.cell.arms
        self.robots = tuple(a.name for a in self.arms)
        self.joint_names = tuple(n for a in self.arms for n in a.joint_names)
        self._gravity = [float(v) for v in cfg['gravity']]
        self._eps = float(cfg['friction_smoothing'])
        # the plant's friction per joint, both arms, as the physics loop uses it (plain floats)
        self._viscous = [float(v) for a in self.arms for v in a.viscous]
        self._coulomb = [float(c) for a in self.arms for c in a.coulomb]
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
        world = load_world(pb, self.cell, self.joint_names)
        self._body, self._jidx, self._quill = world.body, world.joints, world.quills
        if gui:
            pb.resetDebugVisualizerCamera(6.0, 30.0, -40.0,
                                          [float(self.arms[0].base[0, 3]), 0.0, 0.3])
        # bound calls for the hot loop (BulletClient builds a partial on every attribute access)
        self._get_states = pb.getJointStates
        self._set_motors = pb.setJointMotorControlArray
        self._step_sim = pb.stepSimulation
        # state
        self._steps = 0
        self.servo = Servo(self.arms, self.ctl_cfg, self.control_mode, -self._gravity[2],
                           self._eps, self._servo_dt, self._read()[0],
                           float(self.sim_cfg['velocity_tolerance']),
                           float(self.sim_cfg['start_tolerance']),
                           margin=self.admission_margin, physics_dt=self.dt)
        self.conveyor = Conveyor(pb, self.cell, self.sim_cfg, lambda: self.time, world.body,
                                 world.belt, world.link_names, self._seed)
        self.grippers = Grippers(pb, self.conveyor, world.body, world.quills, self.robots,
                                 float(self.sim_cfg['grasp_tolerance']))

    @property
    def body(self) -> int:
        """Return the cell's multibody in :attr:`client`'s world (the arms; the rest merged)."""
        return self._body

    @property
    def client(self) -> BulletClient:
        """Return the PyBullet connection of the simulator, for rendering; only step() steps it."""
        return self._pb

    # --- clock and stepping ---------------------------------------------------------------
    @property
    def time(self) -> float:
        """Sim time, s (physics steps taken times the step)."""
        return self._steps * self.dt

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps (servo, friction, items included)."""
        body, idx = self._body, self._jidx
        get_states, set_motors, step_sim = self._get_states, self._set_motors, self._step_sim
        torque, servo, eps = pybullet.TORQUE_CONTROL, self.servo, self._eps
        viscous, coulomb = self._viscous, self._coulomb
        shape = servo.tau.shape
        for _ in range(int(n)):
            states = get_states(body, idx)
            qd = [s[1] for s in states]
            if self._steps % self._servo_every == 0:
                servo.update(self._steps * self.dt,
                             np.array([s[0] for s in states]).reshape(shape),
                             np.array(qd).reshape(shape), self.grippers.payload)
            set_motors(body, idx, torque, forces=applied_efforts(
                servo.tau.ravel().tolist(), viscous, coulomb, qd, eps))
            step_sim()
            self._steps += 1
            if self._steps % self._item_every == 0:
                self.conveyor.update()

    def _read(self) -> Tuple[np.ndarray, np.ndarray]:
        states = self._get_states(self._body, self._jidx)
        q = np.array([s[0] for s in states]).reshape(-1, 3)
        qd = np.array([s[1] for s in states]).reshape(-1, 3)
        return q, qd

    # --- arms -----------------------------------------------------------------------------
    def _index(self, robot: str) -> int:
        return robot_index(self.robots, robot)

    def joint_state(self) -> JointStateSample:
        """Positions, velocities and applied motor efforts of all six joints (see the type)."""
        q, qd = self._read()
        return JointStateSample(self.joint_names, q.ravel(), qd.ravel(),
                                self.servo.tau.ravel().copy())

    def arm_state(self, robot: str) -> Tuple[np.ndarray, np.ndarray]:
        """Measured ``(q, qd)`` of one arm, each ``(3,)``."""
        a = self._index(robot)
        q, qd = self._read()
        return q[a], qd[a]

    def reference(self, robot: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the servo's reference ``(q, qd, qdd)`` of one arm (as of the last tick)."""
        return self.servo.reference(self._index(robot))

    def execute(self, robot: str, t: ArrayLike, q: ArrayLike, qd: Optional[ArrayLike] = None,
                qdd: Optional[ArrayLike] = None, move_id: str = '', stamp: float = 0.0):
        """Run a joint trajectory on one arm, replacing the running one (:meth:`Servo.execute`).

        :param robot: arm name, e.g. ``scara_left``.
        :param t: ``(N,)`` absolute sim times, s; :param q: ``(N, 3)`` joint positions;
        :param qd, qdd: ``(N, 3)`` or ``None``.
        :param move_id: the move's name; :param stamp: the start it asked for (0: now).
        :return: the :class:`~scara_collab.core.motion.Move` it preempts, if any
            (:meth:`scara_collab.core.motion.CellMotion.take`).
        :raises TrajectoryError: (a ``ValueError``) with the reason (:meth:`Servo.execute`);
            :class:`~scara_collab.core.motion.Refused` if it would bring the arms within
            :attr:`admission_margin`. The arm keeps doing what it did.
        """
        return self.servo.execute(self._index(robot), t, q, qd, qdd, *self._read(), self.time,
                                  move_id, stamp)

    @property
    def motion(self):
        """The arms' commitments (:class:`~scara_collab.core.motion.CellMotion`)."""
        return self.servo.motion

    def hold(self, robot: str) -> None:
        """Drop the running trajectory and hold the arm where it is now."""
        a = self._index(robot)
        self.servo.hold(a, self._read()[0][a])

    def active(self, robot: str) -> bool:
        """Return ``True`` while the arm has a trajectory to run (also before its start time)."""
        return self.servo.active(self._index(robot), self.time)

    def set_estop(self, on: bool) -> None:
        """Emergency stop: both arms brake at their acceleration limits and then hold.

        While it is set, new trajectories are refused unless they part the arms (see
        :meth:`execute`; :meth:`scara_collab.sim.servo.Servo.set_estop`).
        """
        self.servo.set_estop(on, *self._read(), self.time)

    def brake(self, robot: str) -> None:
        """Drop the running trajectory: brake every joint at its acceleration limit, then hold.

        The stop of :func:`scara_collab.core.safety.braking` from the measured state.
        """
        a = self._index(robot)
        q, qd = self._read()
        self.servo.brake(a, q[a], qd[a], self.time)

    @property
    def estop(self) -> bool:
        """``True`` while the emergency stop is set."""
        return self.servo.estop

    def reset_arm(self, robot: str, q: ArrayLike, qd: Optional[ArrayLike] = None) -> None:
        """Teleport an arm to ``q`` ``(3,)`` and hold that position (tests, benchmarks).

        :param qd: ``(3,)`` joint velocities to start with (default at rest).
        :raises TrajectoryError: for an unknown robot, a bad or out-of-limit ``q``, or while
            the gripper holds an item.
        """
        a = self._index(robot)
        arm = self.arms[a]
        point = validate_trajectory([self.time], [q], None if qd is None else [qd], arm.lower,
                                    arm.upper, arm.max_velocity)
        q, qd = point.q, point.qd
        if self.grippers.held[a] is not None:
            raise TrajectoryError(f'{robot} holds item {self.grippers.held[a]}: release it first')
        for j, idx in enumerate(self._jidx[3 * a:3 * a + 3]):
            self._pb.resetJointState(self._body, idx, float(q[0, j]), float(qd[0, j]))
        self.servo.reset(a, self._read()[0][a])

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
