"""``pybullet_bridge``: the simulated cell, standing in for Gazebo and ros2_control.

It is the clock: it steps PyBullet at the physics rate and publishes ``/clock``, so the graph
runs on sim time, at ``real_time_factor`` times real time, or as fast as the machine allows
(``real_time_factor: 0``).

Publishes ``/clock``, ``/joint_states`` (all six joints, ``state_rate``), ``/conveyor/items``
(MarkerArray), ``/conveyor/events`` (one :class:`~scara_collab.nodes.protocol.ItemEvent` per
item event, :data:`~scara_collab.core.sorting.ITEM_EVENTS`; the one source of the run's
counts) and ``/<robot>/execution_status``
(:class:`~scara_collab.nodes.protocol.ExecutionStatus` for the move named in the trajectory's
``header.frame_id``: accepted, refused, finished, preempted, held). Subscribes
``/<robot>/joint_trajectory`` (executed like ros2_control's joint trajectory controller: stamp
zero = start now, else at the stamp; a new trajectory replaces the running one; a bad one, or
one that would bring the arms within the margin, is refused with the reason and the arm keeps
its current command: :mod:`scara_collab.nodes.execution`), ``/emergency_stop`` and
``/protective_stop`` (transient local; true = both arms brake and hold). Serves
``/<robot>/gripper`` (std_srvs/SetBool: true = grasp, false = release), idempotent: a grasp
while holding an item and a release with an empty gripper succeed and say so, so a client may
repeat a request whose answer was lost.
``/sim/pause``, ``/sim/resume``, ``/sim/step`` and ``/sim/reset`` (std_srvs/Trigger) control
the simulation (:mod:`scara_collab.nodes.sim_control`).

Lockstep (:mod:`scara_collab.nodes.lockstep`): the nodes on sim time answer each clock
on ``sim/lockstep``, and the bridge never steps more than ``lockstep_window`` sim seconds
(default 0.02, 0 = off) beyond the oldest answer, so a node that is computing holds sim time
instead of falling behind it. A node that keeps sim time waiting for ``lockstep_timeout`` wall
seconds (per node: ``lockstep_timeouts``, e.g. ``['collision_monitor:2.0']``) is no longer
waited for; the wait is counted for each node on its own, so one frozen node does not take the
others down. The arms never move without the nodes named in ``lockstep_guards`` (default
``['collision_monitor']``): before such a node is dropped, or when it leaves, both arms are
held (status ``held``, reason ``<node> silent ...: holding``) and trajectories are refused
until it answers again (status ``cleared``). The nodes named in ``lockstep_expect`` are waited
for from the start (as if they had answered sim time 0), so the first steps do not depend on
how soon they answer; the launcher and the in-process job name the nodes they start.

In a line of cells (``line_cell``, ``line_upstream``, ``line_downstream``, ``line_timeout``;
:mod:`scara_collab.nodes.line_link`) the bridge hands on what passes its belt's end on
``line/handoff``, takes what the cell upstream hands on, and never steps past the upstream
frontier plus the transit between sections, together with its own lockstep gate.
"""
import math
import time
from typing import Dict, List, Optional

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Bool
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.config import Rule
from scara_collab.core.kinematics import within_limits
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.model import load_cell
from scara_collab.graph import MONITOR_LINKS
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.bridge_outputs import BridgeOutputs
from scara_collab.nodes.bridge_people import BridgePeople, SCALING_MODES
from scara_collab.nodes.execution import Execution, Holds
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.line_link import LineLink
from scara_collab.nodes.lockstep import LockstepGate, parse_timeouts
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import EVENTS, LATCHED
from scara_collab.nodes.runner import run_node
from scara_collab.nodes.sim_control import SimControl
from scara_collab.nodes.trajectory_action import trajectory_actions, TrajectoryActions
from scara_collab.sim.cell_sim import CellSim

#: the bridge's own parameters (the config files' keys come from ``declare_config``)
PARAMETERS = {
    'profile': '',
    'markers_rate': 10.0,                 # Hz of sim time, /conveyor/items
    'step_chunk': 0.01,                   # sim s stepped per bridge tick
    'home': [0.0, 1.5708, 0.0],           # leader joints; the follower mirrored
    'lockstep_window': 0.02,              # sim s, 0 = no lockstep
    'lockstep_timeout': 5.0,              # wall s before a silent participant is dropped
    'line_cell': 0,                       # this cell's index along a line of cells
    'line_upstream': False,               # a cell upstream hands items on (line/upstream)
    'line_downstream': False,             # hand on what passes the belt's end (line/handoff)
    'line_timeout': 5.0,                  # wall s of upstream silence taken for its death
    'person': '',                         # a person in the cell: a scenario or a YAML file
    'person_seed': -1,                    # its seed (random); -1: config/people.yaml's
    'speed_scaling': 'arm',               # each arm its own factor while apart, or one (cell)
    'scaling_timeout': 0.1,               # sim s a speed factor stays valid once heard
    'monitor_link': 'wired',              # the separation monitor in this process, or topics
    'slip_at': '',                        # sim s at which a held item slips ('12.5,30')
    'slip_rate': 0.0,                     # slips per second of carrying (seeded)
}
RULES = (Rule('profile', 'text'), Rule('markers_rate', 'positive'),
         Rule('step_chunk', 'positive'), Rule('home', 'vec3'),
         Rule('lockstep_window', 'nonneg'), Rule('lockstep_timeout', 'positive'),
         Rule('line_cell', 'int'), Rule('line_upstream', 'bool'),
         Rule('line_downstream', 'bool'), Rule('line_timeout', 'positive'),
         Rule('person', 'text'), Rule('person_seed', 'int'),
         Rule('speed_scaling', 'str', lambda v: v in SCALING_MODES,
              f'must be one of {list(SCALING_MODES)}'),
         Rule('scaling_timeout', 'positive'),
         Rule('monitor_link', 'str', lambda v: v in MONITOR_LINKS,
              f'must be one of {list(MONITOR_LINKS)}'),
         Rule('slip_at', 'text'),
         Rule('slip_rate', 'nonneg'))


class Pacer:
    """How many physics steps are due now, to run at a real-time factor.

    :param rtf: sim seconds per wall second, ``0`` = as fast as the machine allows;
    :param dt: s per physics step; :param chunk: steps per tick when unthrottled (and the
        most a throttled tick catches up by, tenfold, before it starts counting afresh).
    """

    def __init__(self, rtf: float, dt: float, chunk: int):
        """Count from the first :meth:`due`."""
        self.rtf, self.dt, self.chunk = float(rtf), dt, chunk
        self._anchor: Optional[tuple] = None  # (wall, sim) when counting started

    @property
    def period(self) -> float:
        """Wall seconds between stepping ticks: back to back when unthrottled."""
        return 0.0 if self.rtf == 0 else 0.002

    def set_rate(self, rtf: float) -> bool:
        """Change the real-time factor; return True if the tick :attr:`period` changes."""
        before = self.period
        self.rtf = float(rtf)
        self.restart()
        return self.period != before

    def restart(self) -> None:
        """Count afresh from now (after a pause or a change of rate)."""
        self._anchor = None

    def due(self, sim_time: float) -> int:
        """Return the steps due at ``sim_time`` (sim s) to keep the rate."""
        if self.rtf <= 0:
            return self.chunk
        wall = time.monotonic()
        if self._anchor is None:
            self._anchor = (wall, sim_time)
        target = self._anchor[1] + (wall - self._anchor[0]) * self.rtf
        due = int((target - sim_time) / self.dt)
        if due > 10 * self.chunk:  # the machine cannot keep up: do not try to catch up
            self._anchor = (wall, sim_time)
            due = self.chunk
        return max(due, 0)


def busy(sim: CellSim) -> str:
    """Return why the arms cannot be reset now (a move runs, an item is held), or ''."""
    why = [f'{r} is executing a move' for r in sim.robots if sim.active(r)]
    why += [f'{r} holds item {sim.grippers.held_item(r)}' for r in sim.robots
            if sim.grippers.held_item(r) is not None]
    return '; '.join(why)


class PyBulletBridge(Node):
    """The simulator node. ``sim`` is the :class:`CellSim` it owns."""

    def __init__(self, **kwargs):
        """Declare and check the parameters, build the simulator and its topics and services.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ValueError: a home pose outside the joint limits or a lockstep window shorter
            than the clock period.
        """
        super().__init__('pybullet_bridge', **kwargs)
        self.sim: Optional[CellSim] = None
        self.gate: Optional[LockstepGate] = None
        self.actions: Optional[TrajectoryActions] = None
        self.line: Optional[LineLink] = None
        self.people: Optional[BridgePeople] = None
        #: the nodes this one built in its process, to be spun with it (a wired monitor)
        self.companions: List[Node] = []
        try:
            self._setup()
        except BaseException:
            self.destroy_node()  # a refused start leaves no node on the graph, no PyBullet
            raise

    def _setup(self) -> None:
        """Build what :meth:`__init__` says, one part after the other (the builders below)."""
        cfg = declare_config(self, ('simulation', 'controllers', 'people'),
                             dynamic=('real_time_factor', 'feed_interval'),
                             on_change=self._on_config)
        params = declare_checked(self, PARAMETERS, RULES)
        for key, default, what in (
                ('lockstep_timeouts', [''], "per-node lockstep_timeout: ['<node>:<s>', ...]"),
                ('lockstep_guards', ['collision_monitor'], 'nodes the arms never move without'),
                ('lockstep_expect', [''], 'participants waited for from the start')):
            self.declare_parameter(key, default, ParameterDescriptor(
                type=ParameterType.PARAMETER_STRING_ARRAY, description=what))
        sim_cfg, ctl_cfg = cfg['simulation'], cfg['controllers']
        self._build_simulator(sim_cfg, ctl_cfg, params)
        self._build_outputs(sim_cfg, params)
        self._build_execution()
        self._build_people(cfg['people'], params)
        self._build_slips(params, int(sim_cfg['item_seed']))
        window = self._build_gate(params)
        self._build_line(params)
        self._build_control()
        self._publish_due(every=True)
        self.get_logger().info(
            f'cell ready: {len(self.sim.joint_state()[0])} joints, physics '
            f'{sim_cfg["physics_rate"]:.0f} Hz, control {ctl_cfg["control_mode"]}, '
            f'real-time factor {self.pacer.rtf or "unthrottled"}, lockstep '
            f'{f"window {window:.3f} s" if window > 0 else "off"}')

    def _build_simulator(self, sim_cfg: dict, ctl_cfg: dict, params: dict) -> None:
        """Build the cell, its simulator with both arms at home, and the pace of its steps.

        :raises ValueError: a home pose outside the joint limits.
        """
        self.cell = load_cell(params['profile'] or None)
        self.sim = CellSim(self.cell, sim_cfg, ctl_cfg, gui=bool(sim_cfg['gui']))
        home = np.asarray(params['home'], dtype=float)
        self.home = dict(zip((a.name for a in self.cell.arms), (home, mirror_joints(home))))
        for arm in self.cell.arms:
            if not within_limits(arm, self.home[arm.name]):
                raise ValueError(f'home {self.home[arm.name].tolist()} is outside the joint '
                                 f'limits of {arm.name}')
            self.sim.reset_arm(arm.name, self.home[arm.name])
        self.dt = 1.0 / float(sim_cfg['physics_rate'])
        self.pacer = Pacer(float(sim_cfg['real_time_factor']), self.dt,
                           max(1, int(round(float(params['step_chunk']) / self.dt))))

    def _build_outputs(self, sim_cfg: dict, params: dict) -> None:
        """Create the publishers: clock, states, items, diagnostics, events, execution statuses."""
        self.outputs = BridgeOutputs(
            self, self.cell, self.sim, {'clock': float(sim_cfg['clock_rate']),
                                        'state': float(sim_cfg['state_rate']),
                                        'markers': float(params['markers_rate'])},
            lambda: self.status().to_msg(), on_clock=lambda: self.line.publish(self.sim.time))
        self.events_pub = self.create_publisher(DiagnosticStatus, 'conveyor/events', EVENTS)
        self.status_pub: Dict[str, object] = {
            arm.name: self.create_publisher(DiagnosticStatus, f'{arm.name}/execution_status',
                                            EVENTS)
            for arm in self.cell.arms}

    def _build_execution(self) -> None:
        """Build the trajectory execution and the holds, and subscribe what drives them.

        Each arm's ``joint_trajectory``, then the stops (latched).
        """
        self.execution = Execution(self.cell, self.sim, self._report, self.get_logger().warning,
                                   blocked=lambda: self.holds.blocked())
        self.holds = Holds(self.cell, self.sim, self.execution, lambda: self.gate.absent,
                           self.get_logger().warning)
        for arm in self.cell.arms:
            self.create_subscription(
                JointTrajectory, f'{arm.name}/joint_trajectory',
                guarded(self, lambda msg, n=arm.name: self.execution.run(n, msg)), 10)
        for kind in self.holds.stops:
            self.create_subscription(Bool, f'{kind}_stop', guarded(
                self, lambda msg, k=kind: self.holds.on_stop(k, msg.data)), LATCHED)

    def _build_people(self, cfg: dict, params: dict) -> None:
        """Put a person and the safety scanners in the cell, if ``person`` names a scenario.

        Its outputs go on the publications' grids (:class:`BridgePeople`); a cell without a
        person has none of this.
        """
        if params['person'] in ('', 'none'):
            return
        seed = params['person_seed'] if params['person_seed'] >= 0 else None
        self.people = BridgePeople(
            self, self.cell, self.sim, cfg, params['person'], seed,
            {'state': 1.0 / self.outputs.periods['state']}, self.execution.hold,
            params['speed_scaling'], params['scaling_timeout'], params['monitor_link'],
            params['profile'])
        # what the separation monitor decides on comes before the clock of its instant
        self.outputs.add('scan', self.people.rate, self.people.scan, first=True)
        if self.people.monitor is not None:  # wired: it decides there, at every state step
            self.companions.append(self.people.monitor)
            self.outputs.add('separation_monitor', 1.0 / self.outputs.periods['state'],
                             guarded(self.people.monitor, self.people.tick), first=True)
        self.outputs.add('person', float(params['markers_rate']), self.people.ground_truth)

    def _build_slips(self, params: dict, seed: int) -> None:
        """Arm the slips of items from the grippers (``--fault drop@...``), if any.

        :raises ValueError: a ``slip_at`` that is not a list of sim times.
        """
        try:
            self.slip_at = sorted(float(t) for t in params['slip_at'].split(',') if t.strip())
        except ValueError:
            raise ValueError(f"slip_at must be sim times like '12.5,30', got "
                             f"{params['slip_at']!r}") from None
        self.slip_rate = float(params['slip_rate'])
        self._slip_rng = np.random.default_rng(seed + 101)

    def _slips(self) -> None:
        """Let held items slip whose time has come (or by chance, at ``slip_rate``)."""
        now = self.sim.time
        due = bool(self.slip_at) and now >= self.slip_at[0] - 1e-9
        while self.slip_at and now >= self.slip_at[0] - 1e-9:
            self.slip_at.pop(0)
        for robot in self.sim.robots:
            if self.sim.grippers.held_item(robot) is None:
                continue
            chance = self.slip_rate * self.outputs.periods['state']
            if due or (chance > 0 and self._slip_rng.random() < chance):
                item = self.sim.grippers.slip(robot)
                self.get_logger().warning(f'fault injection: item {item} slips from the '
                                          f'{robot} gripper at t={now:.3f} s')

    def _build_gate(self, params: dict) -> float:
        """Build the lockstep gate; return its window (sim s, 0 = off).

        :raises ValueError: a window shorter than the clock period.
        """
        window = float(params['lockstep_window'])
        if 0 < window < self.outputs.periods['clock'] - 1e-9:
            raise ValueError(f'lockstep_window {window} s is shorter than the clock period '
                             f'{self.outputs.periods["clock"]} s: the clock could never advance')
        self.gate = LockstepGate(
            self, window, float(params['lockstep_timeout']),
            on_answer=self._wake,
            timeouts=parse_timeouts(self.get_parameter('lockstep_timeouts').value or [],
                                    self.get_namespace()),
            guards=[g for g in self.get_parameter('lockstep_guards').value or [] if g.strip()],
            on_guard=self.holds.on_guard,
            expect=[n for n in self.get_parameter('lockstep_expect').value or [] if n.strip()])
        return window

    def _build_line(self, params: dict) -> None:
        """Join the line of cells (a lone cell: a link with no neighbour)."""
        if params['line_cell'] < 0:
            raise ValueError(f'line_cell must be >= 0, got {params["line_cell"]}')
        self.line = LineLink(self, self.sim, params['line_cell'], params['line_upstream'],
                             params['line_downstream'], on_news=self._wake,
                             timeout=params['line_timeout'])

    def _build_control(self) -> None:
        """Serve the grippers, the simulation control and the trajectory actions; start stepping.

        The stepping timer runs on wall time (steady), cancelled while paused; a 0.25 s look
        re-arms it while the bridge waits for lockstep answers or for the cell upstream.
        """
        for arm in self.cell.arms:
            self.create_service(
                SetBool, f'{arm.name}/gripper',
                guarded(self, lambda req, res, n=arm.name: self._on_gripper(n, req, res), True))
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = self.create_timer(self.pacer.period, self._tick, clock=self._steady)
        self._parked = False  # the stepping timer is off while the bridge waits for answers
        self.control = SimControl(self, self.sim, self.home, self._advance, self._on_pause,
                                  lambda: busy(self.sim))
        if self.control.paused:  # started paused: /sim/resume starts the stepping timer
            self._timer.cancel()
        self.actions = trajectory_actions(self, self.cell, self.sim, self.execution)
        if self.gate.enabled or self.line.upstream:  # re-arm now and then (a silent
            # participant times out; a late frontier from upstream is looked at again)
            self.create_timer(0.25, self._look, clock=self._steady)

    # --- stepping -------------------------------------------------------------------------
    def _on_config(self, name: str, tree: dict) -> None:
        if name == 'simulation':
            if self.pacer.set_rate(float(tree['real_time_factor'])):  # unthrottled: back to back
                self.destroy_timer(self._timer)
                self._timer = self.create_timer(self.pacer.period, self._tick, clock=self._steady)
                self._parked = False
                if self.control.paused:
                    self._timer.cancel()
            if float(tree['feed_interval']) != self.sim.conveyor.feed.interval:
                self.sim.conveyor.set_feed(float(tree['feed_interval']))

    def _look(self) -> None:
        """Every 0.25 s wall: say the time again while waiting, then step on if allowed.

        A participant whose ``/clock`` subscription matched after the clock was published
        (DDS discovery on a busy machine) would otherwise wait for a clock that never comes,
        and be dropped from the lockstep as silent. The same time again changes nothing else.
        """
        if self._parked and not self.control.paused:
            self.outputs.clock()
        self._wake()

    def _wake(self) -> None:
        """Step on, if the bridge was waiting: an answer came (or the 0.25 s watch looks)."""
        if self._parked and not self.control.paused:
            if self.pacer.rtf <= 0:
                self._tick()  # unthrottled: in this callback, in turn with the messages
            else:
                self._parked = False
                self._timer.reset()

    def _tick(self) -> None:
        """Step what is due and the lockstep allows; wait for the answers without spinning.

        Unthrottled, with participants, the bridge steps to the gate's limit at once and the
        answer that moves the limit steps on (:meth:`_wake`): stepping takes its turn with the
        messages in the executor's order, never when a timer thread looks, so a run in one
        process repeats exactly (docs/realtime.md, *Repeatable runs*).
        """
        if self.control.paused:
            return
        due = self.pacer.due(self.sim.time)
        limit = min(self.gate.limit(self.sim.time), self.line.limit())
        if limit == float('inf'):  # nobody to wait for: the stepping timer runs
            if self._parked:
                self._parked = False
                self._timer.reset()
            self._advance(due)
            return
        allowed = (int(math.floor((limit - self.sim.time) / self.dt + 1e-6))
                   if math.isfinite(limit) else 0)  # -inf: nothing heard from upstream yet
        if self.pacer.rtf <= 0:
            self._advance(allowed)
            self.gate.limit(self.sim.time)  # at the limit: the wait for the answers starts now
        elif allowed > 0 or due <= 0:
            self._advance(min(due, allowed))
            return
        self._parked = True
        self._timer.cancel()

    def _advance(self, due: int) -> None:
        """Step ``due`` physics steps, publishing whatever falls due on the way.

        Never past ``pause_at``: there the simulation pauses, its clock published.
        """
        left = self.control.steps_to_pause(self.dt)
        if left is not None:
            due = min(due, left)
        while due > 0:
            n = min(due, self.outputs.steps_to_next(self.dt))
            self.sim.step(n)
            due -= n
            self._publish_due()
        if left is not None and self.control.steps_to_pause(self.dt) == 0:
            self.outputs.publish_off_grid()  # the instant it pauses at, even off the grid
            self.control.pause_here()

    def _on_pause(self, paused: bool) -> None:
        if paused:
            self._timer.cancel()
        else:
            self.pacer.restart()
            self._parked = False
            self._timer.reset()
        self.outputs.diagnostics.publish(self.status().to_msg())  # no sim s passes while paused

    def status(self) -> proto.SimStatus:
        """Return the simulator's state now (:class:`~scara_collab.nodes.protocol.SimStatus`)."""
        return proto.SimStatus(
            round(self.sim.time, 6), self.control.paused, self.sim.estop,
            sum(self.sim.active(r) for r in self.sim.robots), len(self.sim.conveyor.items()),
            ', '.join(self.gate.absent))

    def _publish_due(self, every: bool = False) -> None:
        """Publish what is due (``every``: everything, now), the item events; poll the moves.

        With a person in the cell, it is posed for now and the speed factors applied first.
        """
        if self.people is not None:
            self.people.step()
        if self.slip_at or self.slip_rate:
            self._slips()
        (self.outputs.publish_all if every else self.outputs.publish_due)()
        for ev in self.sim.conveyor.pop_events():
            self.line.on_event(ev.kind, ev.item, ev.time)
            self.events_pub.publish(proto.ItemEvent(ev.kind, ev.item, ev.cls, ev.time, ev.robot,
                                                    ev.cause).to_msg())
        if self.actions is not None:
            self.actions.tick()
        self.execution.poll()

    # --- callbacks ------------------------------------------------------------------------
    def _report(self, robot: str, state: str, move: str, reason: str = '',
                **times) -> None:
        st = proto.ExecutionStatus(robot, state, move, round(self.sim.time, 6), reason=reason,
                                   **times)
        if st.level() != 'OK':
            self.get_logger().warning(f'{robot}: {st.text()}')
        self.status_pub[robot].publish(st.to_msg())

    def _on_gripper(self, robot: str, req: SetBool.Request, res: SetBool.Response):
        ok, res.message = self.sim.grippers.command(robot, bool(req.data))
        res.success = bool(ok)
        if not ok:
            self.get_logger().warning(f'{robot} gripper: {res.message}')
        return res

    def destroy_node(self) -> bool:
        """Close the simulator with the node (also after a refused start)."""
        if self.gate is not None and self.gate.enabled:
            self.get_logger().info(self.gate.summary())
        if self.line is not None and self.line.active:
            self.get_logger().info(self.line.summary())
        if self.actions is not None:
            self.actions.destroy()  # an action server left alive keeps the node on the graph
        if self.sim is not None:
            self.sim.close()
        for node in self.companions:
            node.destroy_node()
        return super().destroy_node()


def main(args=None) -> None:
    """Run the bridge (``ros2 run scara_collab pybullet_bridge``)."""
    run_node(PyBulletBridge, args)


if __name__ == '__main__':
    main()
