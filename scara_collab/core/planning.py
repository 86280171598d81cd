"""Planning decisions of the motion graph, without ROS: what to move, when, and who yields.

Priority rule (left = leader): a follower move that has not started yields to every leader
move; a leader move yields only to follower motion that starts *before* it (a moving arm
cannot be stopped safely in an instant); at equal start times the leader goes first. "Yield"
means: start later by the smallest delay that keeps the capsules ``margin`` apart over both
moves (:func:`scara_collab.core.collision.smallest_safe_delay`), or refuse if no delay up to
``max_delay`` does.
"""
from dataclasses import dataclass
from typing import Optional, Union

import numpy as np

from scara_collab.core import collision
from scara_collab.core.kinematics import fk, ik, IKError, JOINT_LIMIT
from scara_collab.core.model import ArmModel
from scara_collab.core.trajectory import interp_rows, joint_move, line_move, Trajectory

FRAMES = ('world', 'base')
MODES = ('line', 'joint', 'line_or_joint')


@dataclass(frozen=True)
class Timeline:
    """An arm's committed motion in absolute (sim) time.

    It holds ``q[0]`` before ``t[0]`` and ``q[-1]`` after ``t[-1]``.

    :ivar t: ``(N,)`` absolute times, s, increasing.
    :ivar q: ``(N, 3)`` joint positions.
    """

    t: np.ndarray
    q: np.ndarray

    @staticmethod
    def hold(t: float, q) -> 'Timeline':
        """Return the arm standing still at ``q`` from time ``t`` on."""
        return Timeline(np.array([float(t)]), np.asarray(q, dtype=float).reshape(1, 3))

    @staticmethod
    def of(traj: Trajectory, start: float) -> 'Timeline':
        """Return a trajectory started at absolute time ``start``."""
        return Timeline(start + traj.t, traj.q)

    @property
    def start(self) -> float:
        """First time stamp, s."""
        return float(self.t[0])

    @property
    def end(self) -> float:
        """Last time stamp, s."""
        return float(self.t[-1])

    def at(self, t: Union[float, np.ndarray]) -> np.ndarray:
        """Joint positions at absolute time(s) ``t``: ``(3,)``, or ``(M, 3)`` for ``(M,)``."""
        return interp_rows(t, self.t, self.q)

    def since(self, t: float) -> 'Timeline':
        """Return the motion from time ``t`` on: what is past cannot collide any more.

        The state at ``t`` becomes the first stamp; a timeline that starts later is returned
        as is, one that has ended by ``t`` is a hold at its last pose.
        """
        t = float(t)
        if t <= self.t[0]:
            return self
        if t >= self.t[-1]:
            return Timeline.hold(t, self.q[-1])
        later = self.t > t
        return Timeline(np.concatenate(([t], self.t[later])),
                        np.vstack([self.at(t), self.q[later]]))

    def shifted(self, dt: float) -> 'Timeline':
        """Return the same motion ``dt`` seconds later."""
        return Timeline(self.t + dt, self.q)


@dataclass(frozen=True)
class Plan:
    """A planned move.

    ``traj`` starts at absolute time ``start``, ``delay`` seconds later than asked because of
    the other arm.
    """

    traj: Trajectory
    start: float
    delay: float

    @property
    def timeline(self) -> Timeline:
        """Return the move in absolute time."""
        return Timeline.of(self.traj, self.start)

    @property
    def end(self) -> float:
        """When the move ends, s."""
        return self.start + self.traj.duration


def plan_path(arm: ArmModel, q_start, target, frame: str = 'world', mode: str = 'line',
              dt: float = 0.01, dls_threshold: float = 0.5,
              dls_max_damping: float = 0.15) -> Trajectory:
    """Plan the move from ``q_start`` to a tool ``target`` (straight line or joint move).

    :param frame: ``'world'`` or ``'base'``.
    :param mode: ``'line'`` (straight Cartesian line), ``'joint'`` (joint interpolation) or
        ``'line_or_joint'`` (the line, or a joint move when the goal is reachable but the
        straight line is not: it would leave the joint limits or cross the inner reach).
    :raises IKError: the target or the path is refused, with the reason.
    :raises ValueError: unknown frame or mode.
    """
    if frame not in FRAMES:
        raise ValueError(f'unknown frame {frame!r}')
    if mode in ('line', 'line_or_joint'):
        try:
            return line_move(arm, q_start, target, dt=dt, frame=frame,
                             dls_threshold=dls_threshold, dls_max_damping=dls_max_damping)
        except IKError as exc:
            if mode == 'line' or exc.code != JOINT_LIMIT:
                raise
            # the goal is fine but the straight line is not (joint limits, inner reach)
    if mode in ('joint', 'line_or_joint'):
        goal = ik(arm, target, q_current=q_start, frame=frame).unwrap()
        return joint_move(arm, q_start, goal, dt=dt)
    raise ValueError(f'unknown mode {mode!r}; expected one of {MODES}')


def path_options(trajectory_cfg: dict) -> dict:
    """Return :func:`plan_path`'s keyword options from ``controllers.yaml`` ``trajectory``.

    The planners and the sorting job plan with the same options (the job's plans are offered
    to the planners), so both read them here.

    >>> path_options({'sample_period': 0.01, 'dls_threshold': 0.5, 'dls_max_damping': 0.15,
    ...               'offer_tolerance': 0.002})
    {'dt': 0.01, 'dls_threshold': 0.5, 'dls_max_damping': 0.15}
    """
    return {'dt': float(trajectory_cfg['sample_period']),
            'dls_threshold': float(trajectory_cfg['dls_threshold']),
            'dls_max_damping': float(trajectory_cfg['dls_max_damping'])}


def offered_move(arm: ArmModel, t, q, qd, qdd) -> Trajectory:
    """Return a move offered as a plan (the sorting job's), checked to be a plan of ``arm``.

    The job plans each move with the planners' settings to choose and book it, and offers
    that plan so the planner need not plan the same move again; the planner takes it if it
    :func:`starts_at` the arm's measured joints, else plans to its last point.

    :param t: ``(N,)`` times from the start, s (``t[0] = 0``); :param q: ``(N, 3)``;
    :param qd, qdd: ``(N, 3)`` velocities and accelerations, or None.
    :raises ValueError: not a plan: no velocities or accelerations, the first point not at
        ``t = 0``, or positions outside the joint limits (the reason).
    """
    if qd is None or qdd is None:
        raise ValueError('an offered move needs velocities and accelerations at every point')
    t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
    if t[0] != 0.0:
        raise ValueError(f'an offered move starts at t = 0, not {t[0]:g} s')
    if np.any(q < arm.lower - 1e-9) or np.any(q > arm.upper + 1e-9):
        raise ValueError('an offered move leaves the joint limits')
    return Trajectory(t=t, q=q, qd=np.asarray(qd, dtype=float), qdd=np.asarray(qdd, dtype=float),
                      p=fk(arm, q))


def starts_at(traj: Trajectory, q_now, tolerance: float) -> bool:
    """Return True if ``traj`` starts within ``tolerance`` (rad | m, each joint) of ``q_now``.

    >>> move = Trajectory(np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)),
    ...                   np.zeros((1, 3)))
    >>> starts_at(move, [0.001, 0.0, 0.0], 0.002), starts_at(move, [0.0, 0.01, 0.0], 0.002)
    (True, False)
    """
    return bool(np.all(np.abs(traj.q[0] - np.asarray(q_now, dtype=float)) <= tolerance))


def binds_leader(follower_start: float, leader_start: float) -> bool:
    """Return True if a follower motion starting at ``follower_start`` binds a leader move.

    The priority rule, written once: the leader respects follower motion that starts before
    its own start; one starting at or after it yields (it is judged again when it would take
    over, :meth:`scara_collab.core.motion.CellMotion.advance`).

    >>> binds_leader(1.0, 1.5), binds_leader(1.5, 1.5), binds_leader(2.0, 1.5)
    (True, False, False)
    """
    return follower_start < leader_start


def other_view(other: Timeline, my_start: float, leader: bool) -> Timeline:
    """Return what of the other arm's commitment an arm must respect (the priority rule).

    The follower respects all of the leader's motion. The leader ignores follower motion that
    starts at or after its own start (:func:`binds_leader`: the follower will yield): it sees
    the follower held at its pose at ``my_start``, or its full motion if that started earlier.
    """
    if not leader or binds_leader(other.start, my_start):
        return other
    return Timeline.hold(other.start, other.q[0])


def schedule(me: ArmModel, traj: Trajectory, start: float, other_arm: ArmModel,
             other: Timeline, margin: float, leader: bool,
             max_delay: float = 30.0) -> Optional[Plan]:
    """Find the start of ``traj`` that keeps the arms ``margin`` apart, or None.

    :param start: earliest absolute start time, s.
    :param other: the other arm's committed motion (a hold if it is idle).
    :param leader: ``True`` for the priority arm.
    :return: a :class:`Plan` (``delay`` = extra wait), or None if no delay up to
        ``max_delay`` is safe.
    """
    view = other_view(other, start, leader)
    delay = collision.smallest_safe_delay(other_arm, view.t, view.q, me, start + traj.t,
                                          traj.q, margin, max_delay=max_delay)
    if delay is None:
        return None
    return Plan(traj, start + delay, delay)
