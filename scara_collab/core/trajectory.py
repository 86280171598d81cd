"""Trajectories: joint interpolation (the baseline) and the straight Cartesian line.

The straight line follows the design documents' Lagrange-multiplier trajectory note: at every
point the joint velocity is the minimum-norm solution of ``J q_dot = v``,

    min 1/2 |q_dot|^2  s.t.  J q_dot = v   ->   q_dot = J^T (J J^T)^-1 v,

damped near singularity (DLS), with closed-loop correction of the drift: each step adds
``J^+ (p_line - fk(q))`` and repeats it (Newton) until the tool is on the line, so the planned
path stays on the line to ~1e-12 m instead of accumulating integration error.

Both paths are timed the same way: a time-optimal parameterisation ``s(t)`` of the geometric
path (forward-backward integration in the phase plane ``(s, s_dot^2)``) under every joint's
velocity and acceleration limit, starting and ending at rest. The result is sampled at the
controller period.

Example::

    >>> from scara_collab.core.model import load_cell
    >>> arm = load_cell().leader
    >>> q0, target = np.array([0.0, np.pi / 2, 0.4]), [3.0, -2.5, 0.3]   # from (3.5, -1, 0.3)
    >>> traj = line_move(arm, q0, target)            # world-frame target
    >>> path_metrics(traj, fk(arm, q0), target).max_deviation < 1e-9
    True
"""
from dataclasses import asdict, dataclass
import math
from typing import Optional, Union

import numpy as np

from scara_collab.core.kinematics import (
    dls_solve, fk, ik, IKError, jacobian, JOINT_LIMIT, manipulability, within_limits,
    world_to_base)
from scara_collab.core.model import ArmModel

ArrayLike = Union[np.ndarray, list, tuple]


def interp_rows(x: ArrayLike, xp: ArrayLike, fp: ArrayLike) -> np.ndarray:
    """Interpolate the rows ``fp`` ``(N, k)``, given at ``xp`` ``(N,)``, linearly at ``x``.

    Each column is :func:`numpy.interp`: ``xp`` increasing, the first row held before
    ``xp[0]`` and the last after ``xp[-1]``; e.g. joint states ``(N, 3)`` stamped ``xp`` at
    times ``x``.

    :param x: a scalar or ``(M,)`` points.
    :param xp: ``(N,)`` increasing abscissae, ``N >= 1``.
    :param fp: ``(N, k)`` rows.
    :return: ``(k,)`` for a scalar ``x``, else ``(M, k)``.

    >>> interp_rows([0.5, 2.0], [0.0, 1.0], [[0.0, 10.0], [1.0, 20.0]])
    array([[ 0.5, 15. ],
           [ 1. , 20. ]])
    """
    fp = np.asarray(fp, dtype=float)
    return np.stack([np.interp(x, xp, fp[:, j]) for j in range(fp.shape[1])], axis=-1)


@dataclass(frozen=True)
class Trajectory:
    """A timed joint trajectory of one arm, sampled at a fixed period.

    :ivar t: ``(N,)`` time from the start of the move, s (``t[0] = 0``).
    :ivar q, qd, qdd: ``(N, 3)`` joint positions, velocities, accelerations.
    :ivar p: ``(N, 3)`` tool-tip positions in world, m.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    p: np.ndarray

    @property
    def duration(self) -> float:
        """Total time, s."""
        return float(self.t[-1])

    def sample(self, t: ArrayLike) -> np.ndarray:
        """Joint positions at time(s) ``t`` (held before the start and after the end)."""
        return interp_rows(t, self.t, self.q)


@dataclass(frozen=True)
class PathMetrics:
    """How a tool path compares with the straight segment between its ends.

    :ivar max_deviation: largest distance of the tool from the segment, m.
    :ivar path_length: length of the tool path, m.
    :ivar straight_length: length of the segment, m.
    :ivar duration: s.
    :ivar peak_speed: ``(3,)`` peak absolute joint velocity.
    :ivar peak_acceleration: ``(3,)`` peak absolute joint acceleration.
    :ivar rms_jerk: RMS norm of the tool's jerk, m/s^3 (smoothness).
    """

    max_deviation: float
    path_length: float
    straight_length: float
    duration: float
    peak_speed: np.ndarray
    peak_acceleration: np.ndarray
    rms_jerk: float

    def as_dict(self) -> dict:
        """Plain-Python copy (lists, floats) for JSON reports."""
        return {k: (v.tolist() if isinstance(v, np.ndarray) else float(v))
                for k, v in asdict(self).items()}


def segment_deviation(p: ArrayLike, a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Distance of point(s) ``p`` ``(..., 3)`` from the segment ``a``-``b``, m.

    Beyond an end it is the distance from that end::

        >>> segment_deviation([[0.5, 0.2, 0.0], [-1.0, 0.0, 0.0]], [0, 0, 0], [1, 0, 0])
        array([0.2, 1. ])
    """
    p, a, b = (np.asarray(x, dtype=float) for x in (p, a, b))
    ab = b - a
    denom = float(ab @ ab)
    s = np.clip(((p - a) @ ab) / denom, 0.0, 1.0) if denom > 0 else np.zeros(p.shape[:-1])
    return np.linalg.norm(p - (a + s[..., None] * ab), axis=-1)


def path_metrics(traj: Trajectory, start: Optional[ArrayLike] = None,
                 end: Optional[ArrayLike] = None) -> PathMetrics:
    """Deviation from the straight line, length, duration, peak joint rates, jerk."""
    p = traj.p
    start = p[0] if start is None else np.asarray(start, dtype=float)
    end = p[-1] if end is None else np.asarray(end, dtype=float)
    jerk = np.zeros(1)
    if len(traj.t) > 3:
        dt = np.diff(traj.t).mean()
        jerk = np.linalg.norm(np.diff(p, n=3, axis=0), axis=1) / dt ** 3
    return PathMetrics(
        max_deviation=float(segment_deviation(p, start, end).max()),
        path_length=float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()),
        straight_length=float(np.linalg.norm(end - start)),
        duration=traj.duration,
        peak_speed=np.abs(traj.qd).max(axis=0),
        peak_acceleration=np.abs(traj.qdd).max(axis=0),
        rms_jerk=float(np.sqrt(np.mean(jerk ** 2))),
    )


def _accel_coefficients(dq, d2q, amax):
    """Return the ``s_ddot`` bounds of each grid point and joint as lines in ``x = s_dot^2``.

    ``|dq s_ddot + d2q x| <= amax`` is ``c + d x <= s_ddot <= -c + d x`` with
    ``c = -amax / |dq|`` and ``d = -d2q / dq``. A joint that does not move along the path
    (``|dq| <= 1e-12``) bounds nothing here (``c = -inf``, ``d = 0``).

    :return: ``(c, d)``, each ``(M, 3)``.
    """
    moving = np.abs(dq) > 1e-12
    safe = np.where(moving, dq, 1.0)
    c = np.where(moving, -amax / np.abs(safe), -np.inf)
    d = np.where(moving, -d2q / safe, 0.0)
    return c, d


def _max_sdot_sq(dq, d2q, vmax, amax):
    """Largest ``x = s_dot^2`` per grid point allowed by velocity and acceleration limits.

    The ``s_ddot`` interval is non-empty while ``c_j + d_j x <= -c_k + d_k x`` for every pair
    of joints (:func:`_accel_coefficients`), i.e. ``x <= (-c_j - c_k) / (d_j - d_k)`` wherever
    ``d_j > d_k``: the exact bound, in closed form.
    """
    with np.errstate(divide='ignore'):
        xv = np.min(np.where(np.abs(dq) > 1e-12, (vmax / np.abs(dq)) ** 2, np.inf), axis=1)
    c, d = _accel_coefficients(dq, d2q, amax)
    num = -c[:, :, None] - c[:, None, :]  # (M, j, k), >= 0; inf with a joint that stays
    den = d[:, :, None] - d[:, None, :]
    with np.errstate(invalid='ignore'):
        xa = np.where((den > 0) & np.isfinite(num), num / np.where(den > 0, den, 1.0), np.inf)
    return np.minimum(np.where(np.isfinite(xv), xv, 1e6), xa.reshape(len(dq), -1).min(axis=1))


def time_optimal_scaling(s: np.ndarray, dq: np.ndarray, d2q: np.ndarray, vmax: ArrayLike,
                         amax: ArrayLike) -> np.ndarray:
    """Fastest ``s_dot`` along a path ``q(s)`` under joint velocity and acceleration limits.

    Classic phase-plane forward-backward integration on ``x = s_dot^2`` (Bobrow, Shin and
    McKay): the backward pass decelerates as hard as allowed into the end (``x = 0``), the
    forward pass accelerates as hard as allowed from rest, each capped by the maximum
    velocity curve. Between grid points ``x`` changes linearly in ``s`` (constant
    ``s_ddot``). Both passes take the bound as it is, also where the path needs
    deceleration to stay within the acceleration limits (holding speed there instead
    overshot the limits and cost a uniform stretch of the whole move: up to 1.23x TOPP-RA;
    now within 1 % of toppra, ``test/test_topp.py``). The passes are sequential, so they run
    on plain floats with the bounds as precomputed lines in ``x`` (:func:`_accel_coefficients`).

    :param s: ``(M,)`` increasing path parameter.
    :param dq: ``(M, 3)`` ``dq/ds``; :param d2q: ``(M, 3)`` ``d2q/ds2``.
    :param vmax, amax: ``(3,)`` joint limits.
    :return: ``(M,)`` ``s_dot`` (0 at both ends).
    """
    vmax, amax = np.asarray(vmax, float), np.asarray(amax, float)
    if dq.shape[1:] != (3,):
        raise ValueError(f'dq must be (M, 3), got {dq.shape}')
    xmax = _max_sdot_sq(dq, d2q, vmax, amax).tolist()
    ds = np.diff(s).tolist()
    c, d = _accel_coefficients(dq, d2q, amax)
    c0, c1, c2 = c.T.tolist()
    d0, d1, d2 = d.T.tolist()
    m = len(s)
    # the max / min of three below are written out: the same result as the builtins (the
    # first extreme value wins), without a call per grid point (a third of a move's planning)
    back = [0.0] * m  # decelerate as hard as allowed into the end
    xb = 0.0
    for i in range(m - 2, -1, -1):
        j = i + 1
        u, v = c0[j] + d0[j] * xb, c1[j] + d1[j] * xb
        if v > u:
            u = v
        v = c2[j] + d2[j] * xb
        if v > u:
            u = v
        v, w = xb - 2.0 * ds[i] * u, xmax[i]
        if v < w:
            w = v
        xb = back[i] = w if w > 0.0 else 0.0
    x = [0.0] * m  # accelerate as hard as allowed from rest, under both caps
    xi = 0.0
    for i in range(m - 1):
        u, v = d0[i] * xi - c0[i], d1[i] * xi - c1[i]
        if v < u:
            u = v
        v = d2[i] * xi - c2[i]
        if v < u:
            u = v
        w, v = back[i + 1], xmax[i + 1]
        if v < w:
            w = v
        v = xi + 2.0 * ds[i] * u
        if v < w:
            w = v
        xi = x[i + 1] = w if w > 0.0 else 0.0
    return np.sqrt(np.maximum(np.asarray(x), 0.0))


def _timed(arm: ArmModel, s, q_of_s, dq, d2q, dt: float, refine=None) -> Trajectory:
    """Time a geometric path ``q(s)``, sample it every ``dt``, and check the limits.

    Between grid points ``s_ddot`` is constant, so ``s(t)`` is evaluated exactly (piecewise
    quadratic) and ``q_dot = q' s_dot``, ``q_ddot = q' s_ddot + q'' s_dot^2`` come from the
    path derivatives, not from finite differences. If a sampled rate still exceeds a limit by
    more than rounding (the grid is finite), time is stretched uniformly until none does.
    """
    vmax, amax = arm.max_velocity, arm.max_acceleration
    sdot = time_optimal_scaling(s, dq, d2q, vmax, amax)
    ds = np.diff(s)
    seg = 2.0 * ds / np.maximum(sdot[:-1] + sdot[1:], 1e-12)
    u = (sdot[1:] ** 2 - sdot[:-1] ** 2) / (2.0 * ds)  # s_ddot on each interval
    t_grid = np.concatenate(([0.0], np.cumsum(seg)))
    stretch = 1.0
    for _ in range(20):
        total = t_grid[-1] * stretch
        n = max(int(np.ceil(total / dt - 1e-9)), 1)
        t = np.linspace(0.0, total, n + 1)
        tau = t / stretch
        i = np.clip(np.searchsorted(t_grid, tau, side='right') - 1, 0, len(u) - 1)
        h = tau - t_grid[i]
        s_t = np.minimum(s[i] + sdot[i] * h + 0.5 * u[i] * h * h, s[-1])
        sd_t = np.maximum(sdot[i] + u[i] * h, 0.0) / stretch
        sdd_t = u[i] / stretch ** 2
        sd_t[[0, -1]] = 0.0
        q = interp_rows(s_t, s, q_of_s)
        if refine is not None:
            q = refine(s_t, q)
        dq_t, d2q_t = interp_rows(s_t, s, dq), interp_rows(s_t, s, d2q)
        qd = dq_t * sd_t[:, None]
        qdd = dq_t * sdd_t[:, None] + d2q_t * (sd_t ** 2)[:, None]
        ratio = max(np.max(np.abs(qd) / vmax), np.sqrt(np.max(np.abs(qdd) / amax)))
        if ratio <= 1.0:
            break
        stretch *= ratio * (1.0 + 1e-6)
    return Trajectory(t=t, q=q, qd=qd, qdd=qdd, p=fk(arm, q))


def _grid(length: float, step: float = 0.002, minimum: int = 200) -> np.ndarray:
    return np.linspace(0.0, 1.0, max(minimum, int(np.ceil(length / step)) + 1))


def joint_move(arm: ArmModel, q0: ArrayLike, q1: ArrayLike, dt: float = 0.01) -> Trajectory:
    """Baseline: straight in joint space, all joints synchronised, time-optimal.

    :param q0, q1: start and goal joint vectors ``(3,)`` (inside the limits).
    :param dt: sample period, s.
    :raises IKError: if an end is outside the joint limits.
    """
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    if not (within_limits(arm, q0) and within_limits(arm, q1)):
        raise IKError(JOINT_LIMIT, 'joint move end outside the limits')
    s = _grid(float(np.linalg.norm(q1 - q0)))
    dq = np.broadcast_to(q1 - q0, (len(s), 3)).copy()
    if not np.any(dq):  # nothing to move: hold for one sample
        q = np.stack([q0, q0])
        zeros = np.zeros((2, 3))
        return Trajectory(t=np.array([0.0, dt]), q=q, qd=zeros, qdd=zeros, p=fk(arm, q))
    return _timed(arm, s, q0 + s[:, None] * (q1 - q0), dq, np.zeros_like(dq), dt)


def _closest_to_axis(arm: ArmModel, a: np.ndarray, b: np.ndarray) -> float:
    """Smallest horizontal distance of the segment a-b (base frame) from the shoulder axis."""
    a2, b2 = a[:2], b[:2]
    ab = b2 - a2
    denom = float(ab @ ab)
    s = 0.0 if denom == 0 else float(np.clip(-(a2 @ ab) / denom, 0.0, 1.0))
    return float(np.linalg.norm(a2 + s * ab))


def _scalar_damping(w: float, threshold: float, max_damping: float) -> float:
    """Return :func:`scara_collab.core.kinematics.dls_damping` for one float, without numpy."""
    ratio = 1.0 - w / threshold
    return max_damping * (0.0 if ratio < 0.0 else 1.0 if ratio > 1.0 else ratio)


def _follow_line_base(arm: ArmModel, q0: np.ndarray, points: np.ndarray, threshold: float,
                      max_damping: float, iterations: int) -> list:
    """Run the Newton loop of :func:`follow_line` in the base frame with plain floats.

    The same maths as :func:`scara_collab.core.kinematics.dls_solve` on one state: in the base
    frame ``J`` is block diagonal, the planar 2x2 block ``[[a, b], [c, d]]`` (``a = -y``,
    ``c = x`` of the tool, ``b = -L2 s12``, ``d = L2 c12``) and ``dz/dd3 = -1``, so
    ``q_dot = J^T (J J^T + lambda^2 I)^-1 e`` is a closed-form 2x2 solve
    (``det(J J^T) = w^2``, ``w = L1 L2 sin(theta2)``) plus ``q_dot3 = -e_z / (1 + lambda^2)``.
    The result equals the world-frame step because ``J_world = R J_base`` with ``R``
    orthogonal: ``J_w^T (J_w J_w^T + lambda^2 I)^-1 R e = J^T (J J^T + lambda^2 I)^-1 e``.

    :return: ``M`` joint states as ``[theta1, theta2, d3]`` lists.
    """
    l1, l2, z0 = arm.l1, arm.l2, arm.tool_z0
    l1l2 = l1 * l2
    t1, t2, d3 = (float(v) for v in q0)
    out = [[t1, t2, d3]]
    for px, py, pz in world_to_base(arm, points[1:]).tolist():
        for _ in range(iterations):
            t12 = t1 + t2
            c1, s1, c12, s12 = math.cos(t1), math.sin(t1), math.cos(t12), math.sin(t12)
            b, d = -l2 * s12, l2 * c12
            x, y = l1 * c1 + d, l1 * s1 - b  # tool position; the block's a = -y, c = x
            ex, ey, ez = px - x, py - y, pz - (z0 - d3)
            w = abs(l1l2 * math.sin(t2))
            lam2 = _scalar_damping(w, threshold, max_damping) ** 2
            m00, m01, m11 = y * y + b * b + lam2, -y * x + b * d, x * x + d * d + lam2
            det = w * w + lam2 * (m00 + m11 - lam2)
            y0, y1 = (m11 * ex - m01 * ey) / det, (m00 * ey - m01 * ex) / det
            t1 += -y * y0 + x * y1
            t2 += b * y0 + d * y1
            d3 -= ez / (1.0 + lam2)
        out.append([t1, t2, d3])
    return out


def _follow_line_numpy(arm: ArmModel, q0: np.ndarray, points: np.ndarray, threshold: float,
                       max_damping: float, iterations: int) -> np.ndarray:
    """Run the Newton loop of :func:`follow_line` with numpy, in the world frame.

    :return: ``(M, 3)`` joint states, ``q0`` first.
    """
    q = np.empty((len(points), 3))
    q[0] = q0
    for i in range(1, len(points)):
        qi = q[i - 1]
        for _ in range(iterations):
            qi = qi + dls_solve(arm, qi, points[i] - fk(arm, qi), threshold, max_damping)
        q[i] = qi
    return q


def follow_line(arm: ArmModel, q0: np.ndarray, points: np.ndarray, velocity_dir: np.ndarray,
                threshold: float, max_damping: float, iterations: int = 3):
    """Track world points along a line with min-norm (DLS) steps and Newton correction.

    Each point starts from the previous state and takes ``iterations`` steps
    ``q += J^T (J J^T + lambda^2 I)^-1 (p - fk(q))``: the Lagrange-multiplier (minimum-norm)
    solution of :func:`scara_collab.core.kinematics.dls_solve`. The loop runs in the arm's
    base frame on plain floats (:func:`_follow_line_base`: the same maths, without numpy's
    per-call overhead on one 3-vector, which dominated); the numpy loop
    (:func:`_follow_line_numpy`) remains for a base rotation that is not orthogonal and for
    the arithmetic errors only floats raise (e.g. an exactly singular, undamped ``J``, where
    numpy returns what its solver gives).

    :param q0: ``(3,)`` joint state at ``points[0]``.
    :param points: ``(M, 3)`` desired tool positions.
    :param velocity_dir: ``(3,)`` ``dp/ds`` (constant along a line).
    :return: ``(q (M, 3), dq_ds (M, 3))``.
    """
    q = None
    rot = arm.base[:3, :3]
    if np.allclose(rot.T @ rot, np.eye(3), rtol=0.0, atol=1e-12):
        try:
            q = np.array(_follow_line_base(arm, q0, points, float(threshold), float(max_damping),
                                           iterations))
        except (ArithmeticError, ValueError):
            q = None
    if q is None:
        q = _follow_line_numpy(arm, q0, points, threshold, max_damping, iterations)
    dq = dls_solve(arm, q, np.broadcast_to(velocity_dir, q.shape), threshold, max_damping)
    return q, dq


def _line_path(arm: ArmModel, q0: np.ndarray, points: np.ndarray, delta: np.ndarray,
               threshold: float, max_damping: float):
    """Joint path along the line: the integral curve of the min-norm velocity field.

    The arm is not redundant in (x, y, z), so where no damping acts (manipulability above
    ``threshold`` everywhere) the integral curve of ``q' = J^-1 delta`` through ``q0`` is the
    IK branch that stays continuous with ``q0``: it is evaluated in closed form for all points
    at once (with one vectorised correction step). Where damping would act, the sequential
    DLS integration of :func:`follow_line` is used instead.
    """
    sol = ik(arm, points, q_current=q0)
    if np.all(sol.ok) and np.all(sol.elbow == sol.elbow[0]) \
            and np.min(manipulability(arm, sol.q)) > threshold:
        q = sol.q + dls_solve(arm, sol.q, points - fk(arm, sol.q), threshold, max_damping)
        dq = dls_solve(arm, q, np.broadcast_to(delta, q.shape), threshold, max_damping)
        return q, dq
    return follow_line(arm, q0, points, delta, threshold, max_damping)


def line_move(arm: ArmModel, q0: ArrayLike, target: ArrayLike, dt: float = 0.01,
              frame: str = 'world', dls_threshold: float = 0.5,
              dls_max_damping: float = 0.15) -> Trajectory:
    """Straight Cartesian line from the current state to ``target``, time-optimal.

    :param q0: current joint state ``(3,)``.
    :param target: goal tool position ``(3,)`` in ``frame`` (``'world'`` or ``'base'``).
    :param dt: sample period, s.
    :param dls_threshold, dls_max_damping: see :func:`scara_collab.core.kinematics.dls_damping`.
    :raises IKError: the goal is refused (reason in the exception), the line passes inside
        the inner reach, or the line leaves the joint limits.
    """
    q0 = np.asarray(q0, dtype=float)
    goal = ik(arm, target, q_current=q0, frame=frame)
    goal.unwrap()
    p0 = fk(arm, q0)
    p1 = fk(arm, goal.q)  # world frame either way
    a, b = world_to_base(arm, p0), world_to_base(arm, p1)
    if np.hypot(a[0], a[1]) > arm.reach_max + 1e-9:
        raise IKError(JOINT_LIMIT, f'the start is {np.hypot(a[0], a[1]):.3f} m from the '
                      f'shoulder axis, outside the reach window ({arm.reach_max} m): no '
                      'straight line from there; use a joint move')
    inner = _closest_to_axis(arm, a, b)
    if inner < arm.reach_min:
        raise IKError(JOINT_LIMIT, f'the line passes {inner:.3f} m from the shoulder axis, '
                      f'inside the inner reach {arm.reach_min} m')
    delta = p1 - p0
    length = float(np.linalg.norm(delta))
    if length < 1e-9:
        return joint_move(arm, q0, goal.q, dt)
    s = _grid(length)
    points = p0 + s[:, None] * delta
    q_s, dq = _line_path(arm, q0, points, delta, dls_threshold, dls_max_damping)
    if not np.all(within_limits(arm, q_s, tol=1e-6)):
        raise IKError(JOINT_LIMIT, 'the straight line leaves the joint limits; '
                      'use a joint move or an intermediate point')
    d2q = np.gradient(dq, s, axis=0, edge_order=2)

    def refine(s_t, q):  # exact closed-loop correction at every output sample
        pts = p0 + s_t[:, None] * delta
        for _ in range(3):
            q = q + dls_solve(arm, q, pts - fk(arm, q), dls_threshold, dls_max_damping)
        return q

    return _timed(arm, s, q_s, dq, d2q, dt, refine=refine)


def resolved_rate(arm: ArmModel, q0: ArrayLike, p_ref: ArrayLike, v_ref: ArrayLike, dt: float,
                  gain: float = 0.0, dls_threshold: float = 0.5,
                  dls_max_damping: float = 0.15) -> np.ndarray:
    """Run the design documents' differential-kinematics loop at a fixed timing (no re-timing).

    ``q_dot_k = J^+_dls(q_k) (v_ref_k + gain (p_ref_k - fk(q_k)))``, ``q_{k+1} = q_k +
    q_dot_k dt``. With ``dls_max_damping = 0`` this is the plain pseudo-inverse of the
    trajectory note, whose joint speed blows up near a singularity; DLS bounds it.

    :param p_ref, v_ref: ``(N, 3)`` desired tool positions and velocities (world).
    :return: ``(N, 3)`` joint velocities commanded at each step (positions by cumsum).
    """
    q = np.asarray(q0, dtype=float).copy()
    p_ref, v_ref = np.asarray(p_ref, float), np.asarray(v_ref, float)
    qd = np.empty_like(p_ref)
    for k in range(len(p_ref)):
        v = v_ref[k] + gain * (p_ref[k] - fk(arm, q))
        if dls_max_damping > 0:
            qd[k] = dls_solve(arm, q, v, dls_threshold, dls_max_damping)
        else:
            qd[k] = np.linalg.pinv(jacobian(arm, q)) @ v
        q = q + qd[k] * dt
    return qd
