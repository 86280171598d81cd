"""``/<robot>/follow_joint_trajectory``: ros2_control's trajectory action, served by the bridge.

Where ``control_msgs`` loads (no PyPI wheel: ``scripts/build_interfaces`` builds it; a ROS
install has it; :mod:`scara_collab.nodes.optional_interfaces`), each arm serves
``control_msgs/action/FollowJointTrajectory`` with the joint trajectory controller's
semantics, through the same execution as ``/<robot>/joint_trajectory``
(:class:`scara_collab.nodes.execution.Execution`):

- a goal the trajectory controller would reject is rejected at the goal response, with a
  warning that says why, and nothing runs or stops: no points, joint names that are not
  exactly the arm's three (unknown, missing or repeated), points whose positions (or
  velocities, accelerations) do not match them, times not strictly increasing, non-finite
  numbers, too many points (:func:`scara_collab.nodes.conversions.trajectory_arrays`
  refuses it);
- an accepted goal with a tolerance for a joint not the arm's ends at once with
  ``INVALID_JOINTS``, one the execution refuses (limits, an end already past, a start far
  from the arm, the e-stop) with ``INVALID_GOAL``; the ``error_string`` says why;
- feedback (desired = the servo's reference, actual, error) every ``FEEDBACK_PERIOD`` of sim
  time while it runs;
- a path tolerance broken while it runs holds the arm (braking at the acceleration limits)
  and ends with ``PATH_TOLERANCE_VIOLATED``; at the end every joint must be within its goal
  tolerance by ``goal_time_tolerance`` (default ``GOAL_TIME``) after the end, else
  ``GOAL_TOLERANCE_VIOLATED``; a tolerance of 0 is the default (:data:`GOAL_TOLERANCE` at the
  goal, none on the path), -1 none;
- cancel holds the arm where it is (canceled); a new goal, a trajectory on the topic or the
  e-stop ends the running goal (aborted, saying which).

The moves of goals are named ``<robot>/-<n>`` (the n-th goal): a move id as every status
carries, never one of the job's (those are positive).
"""
from dataclasses import dataclass
import functools
from typing import Dict, List, Optional

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectoryPoint

from scara_collab.core.model import CellModel
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.execution import Execution
from scara_collab.nodes.optional_interfaces import optional_interface
from scara_collab.sim.cell_sim import CellSim

#: no PyPI wheel: built by scripts/build_interfaces, or from a ROS install
FOLLOW_JOINT_TRAJECTORY = optional_interface('control_msgs.action', 'FollowJointTrajectory')
FollowJointTrajectory = FOLLOW_JOINT_TRAJECTORY.type

#: s of sim time between feedback messages
FEEDBACK_PERIOD = 0.1
#: rad | m: the default goal tolerance per joint (a goal tolerance of 0)
GOAL_TOLERANCE = 0.01
#: s after the end by which the joints must be within the goal tolerance (0 in the goal)
GOAL_TIME = 1.0


@dataclass
class _Goal:
    """One arm's running goal."""

    handle: object
    move: str
    end: float
    path: np.ndarray       # per joint; inf = not checked
    goal: np.ndarray
    deadline: float
    done: Future
    next_feedback: float = 0.0
    code: int = 0
    text: str = ''


def _tolerances(names: List[str], given, default: float) -> np.ndarray:
    """Return each joint's position tolerance from ``JointTolerance`` entries.

    :raises ValueError: for a joint that is not one of ``names``.
    """
    out = np.full(len(names), default)
    for tol in given:
        if tol.name not in names:
            raise ValueError(f'tolerance for unknown joint {tol.name!r}')
        if tol.position > 0:
            out[names.index(tol.name)] = tol.position
        elif tol.position < 0:
            out[names.index(tol.name)] = np.inf
    return out


def trajectory_actions(node: Node, cell: CellModel, sim: CellSim,
                       execution: Execution) -> Optional['TrajectoryActions']:
    """Return the action servers of every arm, or ``None`` (said on the log) without the type."""
    if FollowJointTrajectory is None:
        FOLLOW_JOINT_TRAJECTORY.say_absent(node.get_logger(), 'no follow_joint_trajectory '
                                           'action (the joint_trajectory topic still works)')
        return None
    return TrajectoryActions(node, cell, sim, execution)


class TrajectoryActions:
    """The action servers of every arm (see the module docstring).

    :param node: the bridge; :param cell: the cell model; :param sim: its simulator.
    :param execution: the execution both interfaces share.
    """

    def __init__(self, node: Node, cell: CellModel, sim: CellSim, execution: Execution):
        """Serve ``/<robot>/follow_joint_trajectory`` for every arm."""
        self.node, self.cell, self.sim, self.execution = node, cell, sim, execution
        self.active: Dict[str, _Goal] = {}
        self.count = 0
        R = FollowJointTrajectory.Result
        self.codes = {'joints': R.INVALID_JOINTS, 'goal': R.INVALID_GOAL,
                      'path': R.PATH_TOLERANCE_VIOLATED, 'end': R.GOAL_TOLERANCE_VIOLATED}
        self.servers = [ActionServer(
            node, FollowJointTrajectory, f'{arm.name}/follow_joint_trajectory',
            execute_callback=functools.partial(self._execute, arm.name),
            goal_callback=functools.partial(self._goal_response, arm.name),
            cancel_callback=lambda handle: CancelResponse.ACCEPT) for arm in cell.arms]

    def destroy(self) -> None:
        """Destroy the action servers: else they keep the node alive on the graph."""
        for server in self.servers:
            server.destroy()
        self.servers = []

    def _goal_response(self, robot: str, request) -> GoalResponse:
        """Reject a goal whose trajectory the arm cannot take as it is, saying why.

        The one check: the trajectory message's own (``trajectory_arrays``), as the trajectory
        controller's ``validate_trajectory_msg`` rejects such a goal at its goal response.
        """
        try:
            conv.trajectory_arrays(request.trajectory, self.cell.arm(robot).joint_names)
        except conv.MessageError as exc:
            self.node.get_logger().warning(
                f'{robot}/follow_joint_trajectory: goal rejected: {exc}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def _execute(self, robot: str, handle):
        result = FollowJointTrajectory.Result()
        goal = self._start(robot, handle)
        if goal.code == 0 and not goal.done.done():
            await goal.done
        if handle.is_cancel_requested and goal.code == 0:
            handle.canceled()
        elif goal.code == 0:
            handle.succeed()
        else:
            handle.abort()
        result.error_code, result.error_string = goal.code, goal.text
        return result

    def _start(self, robot: str, handle) -> _Goal:
        """Run the goal's trajectory; return its record (``code`` set if it ends at once)."""
        req, arm = handle.request, self.cell.arm(robot)
        self.count += 1
        done = Future()
        goal = _Goal(handle, f'{robot}/-{self.count}', 0.0, np.full(3, np.inf),
                     np.full(3, GOAL_TOLERANCE), 0.0, done)
        names = list(arm.joint_names)  # the trajectory's are these (_goal_response)
        try:
            goal.path = _tolerances(names, req.path_tolerance, np.inf)
            goal.goal = _tolerances(names, req.goal_tolerance, GOAL_TOLERANCE)
        except ValueError as exc:
            return self._end(goal, 'joints', str(exc))
        previous = self.active.pop(robot, None)
        if previous is not None:
            self._end(previous, 'goal', f'preempted by goal {goal.move}')
        msg = req.trajectory
        msg.header.frame_id = goal.move
        span = self.execution.run(robot, msg)
        if span is None:
            return self._end(goal, 'goal', self.execution.reason)
        goal.end = span[1]
        goal.deadline = span[1] + (conv.to_sec(req.goal_time_tolerance) or GOAL_TIME)
        goal.next_feedback = self.sim.time
        self.active[robot] = goal
        return goal

    def _end(self, goal: _Goal, why: Optional[str], text: str) -> _Goal:
        """Finish ``goal``: ``why`` a key of the codes (None: success)."""
        goal.code = 0 if why is None else self.codes[why]
        goal.text = text
        if not goal.done.done():
            goal.done.set_result(text)
        return goal

    def tick(self) -> None:
        """Feedback, tolerances, cancels and ends of the running goals (each state tick)."""
        now = self.sim.time
        for robot, goal in list(self.active.items()):
            q, qd = self.sim.arm_state(robot)
            ref_q, ref_qd, _ = self.sim.reference(robot)
            error = ref_q - q
            running = self.execution.current(robot) == goal.move
            finish = None
            if goal.handle.is_cancel_requested:
                if running:
                    self.execution.hold(robot, f'goal {goal.move} canceled: holding')
                finish = (None, 'canceled: the arm holds where it was')
            elif not running and now < goal.end - 1e-9:
                finish = ('goal', 'ended by another trajectory or the emergency stop')
            elif now < goal.end and np.any(np.abs(error) > goal.path):
                j = int(np.argmax(np.abs(error) - goal.path))
                self.execution.hold(robot, f'goal {goal.move}: path tolerance broken')
                finish = ('path', f'joint {j + 1} is {abs(error[j]):.4f} from its setpoint '
                          f'(path tolerance {goal.path[j]:g}) at t={now:.3f} s')
            elif now >= goal.end - 1e-9 and np.all(np.abs(error) <= goal.goal):
                finish = (None, f'followed to its end at t={goal.end:.3f} s')
            elif now > goal.deadline:
                j = int(np.argmax(np.abs(error) - goal.goal))
                finish = ('end', f'joint {j + 1} is {abs(error[j]):.4f} from its goal '
                          f'(goal tolerance {goal.goal[j]:g}) at t={now:.3f} s')
            if now >= goal.next_feedback or finish is not None:
                goal.next_feedback = now + FEEDBACK_PERIOD
                goal.handle.publish_feedback(self._feedback(robot, now, q, qd, ref_q, ref_qd))
            if finish is not None:
                del self.active[robot]
                self._end(goal, *finish)

    def _feedback(self, robot, now, q, qd, ref_q, ref_qd):
        fb = FollowJointTrajectory.Feedback()
        fb.header.stamp = conv.to_time(now)
        fb.joint_names = list(self.cell.arm(robot).joint_names)

        def point(pos, vel):
            return JointTrajectoryPoint(positions=[float(v) for v in pos],
                                        velocities=[float(v) for v in vel])
        fb.desired, fb.actual = point(ref_q, ref_qd), point(q, qd)
        fb.error = point(ref_q - q, ref_qd - qd)
        return fb
