"""Simulation control services of the bridge: pause, resume, step, reset (std_srvs/Trigger).

Gazebo's world control, for this cell: ``/sim/pause`` stops the clock (no physics step, no
``/clock``; every node on sim time waits), ``/sim/resume`` lets it run again at the bridge's
real-time factor, ``/sim/step`` advances a paused simulation by exactly ``sim_step_count``
physics steps (parameter, default 10 = 10 ms at 1 kHz) and publishes what falls due, and
``/sim/reset`` puts both arms back at their home pose, at rest. All four are idempotent
(pausing a paused simulation succeeds and says so); the answer's message says the sim time.
With the parameter ``paused`` true the bridge starts paused (the launcher starts it so, and
resumes it once the job has started, so a run starts at sim time 0 whatever the start-up
took); with ``pause_at`` > 0 it pauses by itself when sim time reaches it (to the physics
step), once, like ``gz sim --iterations`` (the launcher ends a run's job window there,
whatever the launcher's own turn).
Reset refuses, with the reason, while an arm executes a move or holds an item: that would lose
the move or drop the item outside its bin. Items stay on the belt and sim time runs on (ROS
time never goes back); the feed goes on when the simulation resumes.
"""
from typing import Callable, Dict, Optional

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from std_srvs.srv import Trigger

from scara_collab.nodes.guarded import guarded
from scara_collab.sim.cell_sim import CellSim


class SimControl:
    """The services of the module docstring, on ``node`` for ``sim``.

    :param node: the bridge.
    :param sim: its simulator.
    :param home: each arm's home joints ``(3,)``.
    :param advance: ``advance(n)`` steps the simulation ``n`` physics steps and publishes.
    :param on_pause: ``on_pause(paused)``: the bridge stops or restarts its stepping timer.
    :param busy: ``busy()`` returns why a reset would lose data (``''`` if it would not).
    """

    def __init__(self, node: Node, sim: CellSim, home: Dict[str, np.ndarray],
                 advance: Callable[[int], None], on_pause: Callable[[bool], None],
                 busy: Callable[[], str]):
        """Declare ``sim_step_count`` and serve ``/sim/{pause,resume,step,reset}``."""
        self.node, self.sim, self.home = node, sim, home
        self._advance, self._on_pause, self._busy = advance, on_pause, busy
        self.paused = bool(node.declare_parameter('paused', False, ParameterDescriptor(
            type=ParameterType.PARAMETER_BOOL,
            description='start paused (like gz sim without -r): /sim/resume starts the clock'))
            .value)
        self.pause_at = float(node.declare_parameter('pause_at', 0.0, ParameterDescriptor(
            type=ParameterType.PARAMETER_DOUBLE,
            description='sim time (s) at which to pause by itself, once; 0 = never')).value)
        if not (self.pause_at >= 0.0 and self.pause_at < float('inf')):
            raise ValueError(f'pause_at must be a sim time >= 0 s, got {self.pause_at}')
        node.declare_parameter('sim_step_count', 10, ParameterDescriptor(
            type=ParameterType.PARAMETER_INTEGER,
            description='physics steps one /sim/step call advances (>= 1)'))
        self._step_count()  # refuse a bad value at start
        for name, callback in (('pause', self._pause), ('resume', self._resume),
                               ('step', self._step), ('reset', self._reset)):
            node.create_service(Trigger, f'sim/{name}', guarded(node, callback, service=True))

    def _step_count(self) -> int:
        n = self.node.get_parameter('sim_step_count').value
        if not isinstance(n, int) or n < 1:
            raise ValueError(f'sim_step_count must be an integer >= 1, got {n!r}')
        return n

    def steps_to_pause(self, dt: float) -> Optional[int]:
        """Return the physics steps of ``dt`` left until ``pause_at`` (None: none due)."""
        if self.pause_at <= 0.0:
            return None
        return max(int(round((self.pause_at - self.sim.time) / dt)), 0)

    def pause_here(self) -> None:
        """Pause now, as ``pause_at`` asks (once: a later resume runs on)."""
        self.pause_at = 0.0
        self._set_paused(True, Trigger.Response())

    def _at(self) -> str:
        return f'sim t={self.sim.time:.3f} s'

    def _pause(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        return self._set_paused(True, res)

    def _resume(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        return self._set_paused(False, res)

    def _set_paused(self, paused: bool, res: Trigger.Response) -> Trigger.Response:
        """Pause or resume (idempotent); the answer says which and the sim time."""
        changed = paused != self.paused
        self.paused = paused
        done, already = ('paused', 'already paused') if paused else ('resumed', 'already running')
        if changed:
            self._on_pause(paused)
            self.node.get_logger().info(f'simulation {done} at {self._at()}')
        res.success, res.message = True, f'{done if changed else already} at {self._at()}'
        return res

    def _step(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        if not self.paused:
            res.success, res.message = False, f'refused: running ({self._at()}); pause first'
            return res
        n = self._step_count()
        self._advance(n)
        res.success, res.message = True, f'advanced {n} physics steps to {self._at()}'
        return res

    def _reset(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        why = self._busy()
        if why:
            res.success, res.message = False, f'refused: {why}'
            return res
        for robot, q in self.home.items():
            self.sim.reset_arm(robot, q)
        self.node.get_logger().info(f'arms reset to their home poses at {self._at()}')
        res.success, res.message = True, f'arms at home at {self._at()}'
        return res
