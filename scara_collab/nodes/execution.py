"""The bridge's trajectory execution: what each arm runs, and the statuses that say so.

Executed like ros2_control's joint trajectory controller, by the rules of the cell's
committed-motion model (:mod:`scara_collab.core.motion`): a header stamp of zero starts the
trajectory now, else at the stamp (a stamp in the past starts it at once, with a warning); a
first point after ``t = 0`` is reached from the current state; a new trajectory replaces the
running one from its own start (status ``preempted`` for the old one, at once); a bad one is
refused with the reason and the arm keeps its current command. A trajectory that would bring
the arms within the admission margin against the other arm's committed motion is refused at
the door, whoever sent it; one waiting for its start is judged again when it takes over and,
if it no longer keeps the margin, ``refused`` then (the arm keeps what it ran). Every outcome is an
:class:`~scara_collab.nodes.protocol.ExecutionStatus` for the move named by the trajectory's
``header.frame_id``: ``accepted`` (with its start and end), ``refused``, ``preempted``,
``finished`` (:meth:`Execution.poll`, when its end has passed), ``held``
(:meth:`Execution.hold`).
"""
from typing import Callable, Dict, Optional, Tuple

from trajectory_msgs.msg import JointTrajectory

from scara_collab.core import motion, move_time
from scara_collab.core.model import CellModel
from scara_collab.nodes import conversions as conv
from scara_collab.sim.cell_sim import CellSim

KEEPS = 'not executed: the arm keeps its current command'

#: ``report(robot, state, move, reason='', **times)`` publishes one status
Report = Callable[..., None]


class Execution:
    """The arms' trajectories in ``sim``, reported (see the module docstring).

    What each arm runs, waits to run and was last given is the cell's committed-motion model
    (``sim.motion``, :class:`~scara_collab.core.motion.CellMotion`); this class turns a
    trajectory message into a move the model takes and the model's events into statuses.

    :param cell: the cell model; :param sim: the simulator that executes.
    :param report: publishes a status (:data:`Report`).
    :param warn: logs a warning.
    :param blocked: returns why no move may start now (a lockstep guard is missing), ``''``
        when moves may start; asked for every trajectory, from the topic or an action goal.
    """

    def __init__(self, cell: CellModel, sim: CellSim, report: Report,
                 warn: Callable[[str], None], blocked: Callable[[], str] = lambda: ''):
        """Nothing runs yet."""
        self.cell, self.sim, self.report, self.warn = cell, sim, report, warn
        self.blocked = blocked
        self.reason = ''  # why the last refused trajectory was refused

    def run(self, robot: str, msg: JointTrajectory) -> Optional[Tuple[float, float]]:
        """Execute ``msg`` on ``robot``; return its ``(start, end)``, or None if refused.

        A refusal is reported, and its reason kept in :attr:`reason`.
        """
        move = msg.header.frame_id
        why = self.blocked()
        if why:
            return self._refuse(robot, move, why)
        try:
            stamp, t, q, qd, qdd = conv.trajectory_arrays(msg, self.cell.arm(robot).joint_names)
        except conv.MessageError as exc:
            return self._refuse(robot, move, f'{exc}; {KEEPS}')
        now = self.sim.motion[robot].clock(self.sim.time)  # the arm's trajectory time
        try:
            start = move_time.start_time(stamp, float(t[-1]), now, self.sim.dt)
        except move_time.Refused as exc:
            return self._refuse(robot, move, f'{exc}; {KEEPS}')
        if stamp > 0.0 and start > stamp:
            self.warn(f'{robot}: move {move or "(no id)"} start {stamp:.3f} s is '
                      f'{now - stamp:.3f} s late; starting now if it keeps the margin')
        if t[0] > 0.0:  # like ros2_control: move from the current state to the first point
            q_now, qd_now = self.sim.arm_state(robot)
            t, q, qd, qdd = motion.from_here(t, q, q_now, qd, qdd, qd_now)
        try:
            old = self.sim.execute(robot, start + t, q, qd, qdd, move, stamp)
        except ValueError as exc:
            return self._refuse(robot, move, f'{exc}; {KEEPS}')
        if old is not None:
            self.report(robot, 'preempted', old.id, f'replaced by move {move or "(no id)"}',
                        by=move)
        self.report(robot, 'accepted', move, start=start, end=start + t[-1],
                    stamp=stamp if stamp > 0 else None)
        return start, start + t[-1]

    def _refuse(self, robot: str, move: str, reason: str) -> None:
        self.reason = reason
        self.report(robot, 'refused', move, reason)

    def current(self, robot: str) -> str:
        """Return the id of the move ``robot`` was last given and still has (``''``: none)."""
        latest = self.sim.motion[robot].latest
        return '' if latest is None else latest.id

    def poll(self) -> None:
        """Report the moves dropped at their start (``refused``) and those ended (``finished``)."""
        for robot, event, move, reason in self.sim.motion.poll(self.sim.time):
            if event == 'dropped':
                self._refuse(robot, move.id, f'{reason}; {KEEPS}')
            else:
                self.report(robot, 'finished', move.id)

    def hold(self, robot: str, reason: str) -> None:
        """Brake ``robot`` at its acceleration limits and hold; its move is reported ``held``."""
        move = self.sim.motion.release(robot)
        self.sim.brake(robot)
        brake = self.sim.motion[robot]
        end = None if brake.running is None else round(brake.running.end + brake.lag, 6)
        self.report(robot, 'held', move, reason, end=end)  # at rest from ``end`` on


class Holds:
    """What holds both arms: a standing stop, or a lockstep guard that is missing.

    A stop (emergency or protective, from the collision monitor or anyone) brakes both arms
    at their acceleration limits and drops their moves (status ``held``); while one stands the
    simulator runs only a move that parts the arms. A missing guard holds both arms the same
    way, and no move may start until every guard answers again (:meth:`blocked`). Each end is
    said to both arms (status ``cleared``).

    :param absent: returns the missing guards, name -> why (the lockstep gate's).
    :param warn: logs a warning.
    """

    def __init__(self, cell: CellModel, sim: CellSim, execution: Execution,
                 absent: Callable[[], Dict[str, str]], warn: Callable[[str], None]):
        """No stop stands, no guard is missing."""
        self.cell, self.sim, self.execution = cell, sim, execution
        self.absent, self.warn = absent, warn
        self.stops = {'emergency': False, 'protective': False}

    def on_stop(self, kind: str, on: bool) -> None:
        """Take the latched flag of a stop of ``kind``: hold the arms, or say it is over."""
        self.stops[kind] = bool(on)
        on = any(self.stops.values())
        if on == self.sim.estop:
            return
        held = {a.name: self.sim.motion.release(a.name) for a in self.cell.arms} if on else {}
        self.sim.set_estop(on)
        standing = ' and '.join(k for k, v in self.stops.items() if v)
        for arm in self.cell.arms:
            if on:
                self.execution.report(arm.name, 'held', held[arm.name],
                                      f'{standing} stop: holding')
            else:
                self.execution.report(arm.name, 'cleared', '', f'{kind} stop released')

    def on_guard(self, name: str, present: bool, why: str) -> None:
        """Hold both arms when a guard is missing; say so again when every guard is back."""
        if present and self.absent():
            return  # another guard is still missing
        self.warn(f'lockstep: guard {name} {why}: ' + (
            'trajectories are accepted again' if present
            else 'holding both arms, refusing trajectories'))
        for arm in self.cell.arms:
            if present:
                self.execution.report(arm.name, 'cleared', '', f'{name} {why}')
            else:  # braked at the acceleration limits, as for an e-stop
                self.execution.hold(arm.name, f'{name} {why}: holding')

    def blocked(self) -> str:
        """Return why no move may start (a guard is missing), or ''."""
        absent = self.absent()
        if not absent:
            return ''
        name, why = next(iter(absent.items()))
        return f'{name} {why}: no move until it answers again'
