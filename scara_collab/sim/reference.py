"""Joint references for the simulator: validated trajectories, interpolated between points.

A trajectory arrives as absolute times ``t`` ``(N,)`` and joint positions ``q`` ``(N, 3)``,
optionally with velocities ``v`` and accelerations ``a``. Without velocities, interior points
get central finite differences and both ends zero (the arm starts from a hold and ends in a
hold).

**Two pieces per segment.** Between points ``i`` and ``i + 1`` (``tau = t - t_i``,
``h = t_{i+1} - t_i``) each joint follows two pieces that meet at a switch time ``tau_s`` in
``[0, h]``, each with an acceleration linear in time; the first leaves point ``i``, the second
arrives at point ``i + 1``::

    q(tau) = q_i     + v_i     u + alpha_0 u^2 / 2 + beta_0 u^3 / 6,   u = tau      (tau < tau_s)
    q(tau) = q_{i+1} + v_{i+1} u + alpha_1 u^2 / 2 + beta_1 u^3 / 6,   u = tau - h  (tau >= tau_s)

Its acceleration runs from ``alpha_0`` to ``L`` before the switch and from ``R`` to
``alpha_1`` after it (the four *corners*, ``c = (alpha_0, L, R, alpha_1)``;
``beta_0 = (L - alpha_0) / T1``, ``beta_1 = (alpha_1 - R) / T2``, ``T1 = tau_s``,
``T2 = h - tau_s``). Position and velocity are continuous at the points by construction, and at
the switch when the corners meet two linear conditions, on the velocity change and on the
acceleration's first moment (``dv = v_{i+1} - v_i``, ``dq = q_{i+1} - q_i``)::

    T1 (alpha_0 + L) / 2 + T2 (R + alpha_1) / 2                                   = dv
    T1^2 (alpha_0 + 2 L) / 6 + T1 T2 (R + alpha_1) / 2 + T2^2 (R + 2 alpha_1) / 6 = h v_{i+1} - dq

The acceleration :meth:`HermiteReference.sample` returns is the exact derivative. Its peak in
a segment is the largest corner, and the velocity's is at a point, at the switch or where a
piece's acceleration crosses zero: both exact and cheap, which is how the pieces are chosen and
how :func:`validate_trajectory` checks the velocity limit *between* the points.

**Candidates.** Without accelerations the reference is the cubic Hermite polynomial through both
positions with both velocities (one piece, ``tau_s = h``; ``dq``, ``m = v`` as above)::

    q(tau)  = q_i + m_i tau + a2 tau^2 + a3 tau^3
    a2 = (3 dq / h - 2 m_i - m_{i+1}) / h,    a3 = (m_i + m_{i+1} - 2 dq / h) / h^2

A time-optimal plan is bang-bang: its acceleration jumps between two samples (from ``+a_max``
to ``-a_max``, say), and a cubic's, linear in ``tau``, overshoots the planned one by up to 1.5x
(1.57x the limit over random planned lines). So where accelerations are given, each segment and
joint has these candidates:

- the cubic;
- the *switch model*: ``a_i`` held until ``tau_s = (v_{i+1} - v_i - a_{i+1} h) / (a_i - a_{i+1})``
  (the switch that matches both velocities, where it lies in the segment), ``a_{i+1}`` after,
  plus the smoothstep ``r (3 x^2 - 2 x^3)``, ``x = tau / h``, that takes up the position left
  over, ``r`` (zero for a plan that really switched once there). Its corners are
  ``a_i + k``, ``a_i + k (1 - 2 tau_s / h)``, ``a_{i+1} + k (1 - 2 tau_s / h)``,
  ``a_{i+1} - k``, ``k = 6 r / h^2``;
- scanned pieces: two corners held at the given accelerations and the other two solved from
  the conditions, in three families: ``L`` and ``R`` solved (``alpha_0 = a_i``,
  ``alpha_1 = a_{i+1}``: a ramp on each side of the jump), ``R`` and ``alpha_1`` (``a_i``
  held until the jump) or ``alpha_0`` and ``L`` (``a_{i+1}`` held from it); ``tau_s`` at 17
  points in ``[0.01 h, 0.99 h]``, then three times at 9 around each family's best (down to
  0.001 h apart). A planned acceleration that ramps and switches inside one sample is close to
  one of these, where neither the cubic nor the switch model is. The best per segment and joint
  has the lowest peak acceleration plus the speed it adds above both points' (each relative
  to the joint's largest given acceleration and speed), so a velocity overshoot counts
  against it as much as the same fraction of acceleration.

The reference is the cubic or the switch model, whichever has the lower peak acceleration.
Only where that peak is above the joint's largest given acceleration (by more than 0.2 % of
it) are the scanned pieces tried, and taken if their peak is lower by more than that:
measured against the exact plan, the two follow its acceleration more closely where the scan
gains little (a given acceleration samples a function that jumps, so matching it at any price
overshoots), and the scan costs about 1.5 ms a planned line where it runs. Over 100 random
planned lines resampled 50x (second differences at 0.2 ms) the acceleration stays within
1.0017x the limit, 1.003x over other seeds and joint moves (the cubic or the switch model
alone: 1.043x, 1.055x and 1.105x over three seeds, 1 to 4 lines in 100 over 2 %), and the
velocity within 1.003x.

No PyBullet here: plain numpy, tested alone.
"""
from bisect import bisect_right
from typing import NamedTuple, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

SCAN = np.linspace(0.01, 0.99, 17)  #: switch times first scanned, fractions of the segment
#: half-widths of the finer scans around the best switch time so far (0: the last scan)
SCAN_REFINE = (0.98 / 16, 0.98 / 64, 0.98 / 256, 0.0)
REFINE_POINTS = 9  #: switch times in each finer scan
PREFER = 0.002  #: peak gain (of the joint's largest given acceleration) to leave cubic/switch
SPEED_WEIGHT = 1.0  #: weight of the added speed in the scanned candidates' score


class TrajectoryError(ValueError):
    """A trajectory (or a command) was refused; the message says why."""


def robot_index(robots: Sequence[str], robot: str) -> int:
    """Return the index of ``robot`` among the simulator's ``robots``.

    :raises TrajectoryError: for a robot the cell does not have.
    """
    try:
        return list(robots).index(robot)
    except ValueError:
        raise TrajectoryError(f'unknown robot {robot!r}; the cell has {list(robots)}') from None


def _array(x: ArrayLike, name: str, shape: Tuple[int, ...]) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise TrajectoryError(f'{name} is not numeric') from None
    if a.shape != shape:
        raise TrajectoryError(f'{name} must have shape {shape}, got {a.shape}')
    if not np.all(np.isfinite(a)):
        bad = int(np.argwhere(~np.isfinite(a))[0][0])
        raise TrajectoryError(f'{name} has a non-finite value at point {bad}')
    return a


def hermite_coefficients(t: np.ndarray, q: np.ndarray,
                         qd: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Cubic coefficients ``a2, a3`` ``(N-1, 3)`` of every segment (see the module docstring).

    :param t: ``(N,)`` strictly increasing times, s.
    :param q: ``(N, 3)`` positions; :param qd: ``(N, 3)`` velocities.
    """
    h = np.diff(t)[:, None]
    slope = np.diff(q, axis=0) / h
    a2 = (3.0 * slope - 2.0 * qd[:-1] - qd[1:]) / h
    a3 = (qd[:-1] + qd[1:] - 2.0 * slope) / (h * h)
    return a2, a3


def peak_speed(t: np.ndarray, qd: np.ndarray, a2: np.ndarray, a3: np.ndarray) -> np.ndarray:
    """Largest ``|qd|`` of the cubic Hermite reference per joint, points and segment interiors.

    The velocity is quadratic in ``tau``: its peak inside a segment is at
    ``tau* = -a2 / (3 a3)``.

    :return: ``(3,)`` peak absolute velocity.
    """
    h = np.diff(t)[:, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        ts = np.where(a3 != 0.0, -a2 / (3.0 * np.where(a3 != 0.0, a3, 1.0)), -1.0)
    inside = (ts > 0.0) & (ts < h)
    ts = np.where(inside, ts, 0.0)
    interior = np.where(inside, np.abs(qd[:-1] + 2.0 * a2 * ts + 3.0 * a3 * ts * ts), 0.0)
    return np.maximum(np.abs(qd).max(axis=0), interior.max(axis=0, initial=0.0))


def piece_slopes(h: np.ndarray, ts: np.ndarray,
                 corners: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Jerks ``beta_0, beta_1`` of the two pieces (0 for a piece of zero length).

    :param h: segment lengths, s; :param ts: switch times ``tau_s``, s (broadcast with ``h``).
    :param corners: ``(4, ...)`` accelerations ``alpha_0, L, R, alpha_1``.
    """
    a0, left, right, a1 = corners
    t2 = h - ts
    beta0 = np.divide(left - a0, ts, out=np.zeros(np.broadcast(a0, ts).shape), where=ts > 0.0)
    beta1 = np.divide(a1 - right, t2, out=np.zeros(np.broadcast(a1, t2).shape), where=t2 > 0.0)
    return beta0, beta1


def piece_peaks(h: np.ndarray, v0: np.ndarray, v1: np.ndarray, ts: np.ndarray,
                corners: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Exact peak ``|qdd|`` and ``|qd|`` of two-piece segments (see the module docstring).

    :param h: segment lengths, s; :param v0, v1: velocities at the segments' two ends.
    :param ts: switch times ``tau_s``, s; :param corners: ``(4, ...)`` ``alpha_0, L, R,
        alpha_1``; all broadcast together.
    :return: ``(peak_acceleration, peak_speed)``, each broadcast to the inputs' shape.
    """
    a0, left, right, a1 = corners
    t2 = h - ts
    beta0, beta1 = piece_slopes(h, ts, corners)
    first = np.where(ts > 0.0, np.maximum(np.abs(a0), np.abs(left)), 0.0)
    second = np.where(t2 > 0.0, np.maximum(np.abs(right), np.abs(a1)), 0.0)
    # the velocity peaks at a point, at the switch or where a piece's acceleration is zero
    x0 = np.divide(-a0, beta0, out=np.full(beta0.shape, -1.0), where=beta0 != 0.0)
    x1 = np.divide(-a1, beta1, out=np.full(beta1.shape, 1.0), where=beta1 != 0.0)  # u <= 0
    e0 = np.where((x0 > 0.0) & (x0 < ts), np.abs(v0 + a0 * x0 + 0.5 * beta0 * x0 * x0), 0.0)
    e1 = np.where((x1 < 0.0) & (x1 > -t2), np.abs(v1 + a1 * x1 + 0.5 * beta1 * x1 * x1), 0.0)
    at_switch = np.abs(v0 + a0 * ts + 0.5 * beta0 * ts * ts)
    speed = np.maximum(np.maximum(np.abs(v0), np.abs(v1)),
                       np.maximum(at_switch, np.maximum(e0, e1)))
    return np.maximum(first, second), speed


def _families(x: np.ndarray, h: np.ndarray, dv: np.ndarray, dm: np.ndarray, a0: np.ndarray,
              a1: np.ndarray) -> np.ndarray:
    """Corners ``(4, 3, G, n)`` of the three scanned families at switch times ``x h``.

    The two conditions of the module docstring solved for ``L, R`` (``alpha_0 = a_i``,
    ``alpha_1 = a_{i+1}``), for ``R, alpha_1`` (``alpha_0 = L = a_i``) and for
    ``alpha_0, L`` (``R = alpha_1 = a_{i+1}``).

    :param x: ``(3, G, n)`` switch times as fractions of the segments, per family.
    :param h, dv, dm: ``(n,)`` segment lengths and the conditions' right-hand sides
        (``v_{i+1} - v_i``, ``h v_{i+1} - (q_{i+1} - q_i)``).
    :param a0, a1: ``(n,)`` the given accelerations ``a_i``, ``a_{i+1}``.
    """
    t1 = x * h
    t2 = h - t1
    corners = np.empty((4,) + t1.shape)
    corners[0, 0] = corners[0, 1] = corners[1, 1] = a0
    corners[3, 0] = corners[2, 2] = corners[3, 2] = a1
    # L, R: T1 L / 2 + T2 R / 2 = b_v, T1^2 L / 3 + (T1 T2 / 2 + T2^2 / 6) R = b_m
    u1, u2 = t1[0], t2[0]
    b_v = dv - 0.5 * (u1 * a0 + u2 * a1)
    b_m = dm - u1 * u1 * a0 / 6.0 - u2 * (0.5 * u1 + u2 / 3.0) * a1
    c = u2 * (0.5 * u1 + u2 / 6.0)
    det = u1 * u2 * h / 12.0
    corners[1, 0] = (b_v * c - 0.5 * u2 * b_m) / det
    corners[2, 0] = (0.5 * u1 * b_m - u1 * u1 / 3.0 * b_v) / det
    # R, alpha_1: R + alpha_1 = 2 b_v / T2, R + 2 alpha_1 = 6 (b_m - T1 b_v) / T2^2
    u1, u2 = t1[1], t2[1]
    b_v = dv - u1 * a0
    b_m = dm - 0.5 * u1 * u1 * a0
    total = 2.0 * b_v / u2
    corners[3, 1] = 6.0 * (b_m - u1 * b_v) / (u2 * u2) - total
    corners[2, 1] = total - corners[3, 1]
    # alpha_0, L: alpha_0 + L = 2 b_v / T1, alpha_0 + 2 L = 6 b_m / T1^2
    u1, u2 = t1[2], t2[2]
    b_v = dv - u2 * a1
    b_m = dm - u2 * (u1 + 0.5 * u2) * a1
    total = 2.0 * b_v / u1
    corners[1, 2] = 6.0 * b_m / (u1 * u1) - total
    corners[0, 2] = total - corners[1, 2]
    return corners


def _scanned(h: np.ndarray, dq: np.ndarray, v0: np.ndarray, v1: np.ndarray, a0: np.ndarray,
             a1: np.ndarray, scale_a: np.ndarray, scale_v: np.ndarray):
    """Best scanned two-piece candidate for ``n`` segment-joints (see the module docstring).

    :param h, dq, v0, v1, a0, a1: ``(n,)`` each: length, position change, end velocities and
        given accelerations; :param scale_a, scale_v: ``(n,)`` the joint's largest given
        acceleration and speed.
    :return: ``(peak_acceleration, ts, corners)``, ``(n,)``, ``(n,)``, ``(4, n)``.
    """
    dv, dm = v1 - v0, h * v1 - dq
    ends = np.maximum(np.abs(v0), np.abs(v1))
    x = np.broadcast_to(SCAN[None, :, None], (3, len(SCAN), len(h)))
    for width in SCAN_REFINE:  # a coarse grid, then finer ones around each family's best
        corners = _families(x, h, dv, dm, a0, a1)
        acc, speed = piece_peaks(h, v0, v1, x * h, corners)
        score = acc / scale_a + SPEED_WEIGHT * np.maximum(speed - ends, 0.0) / scale_v
        g = np.argmin(score, axis=1)[:, None]
        x_best = np.take_along_axis(x, g, axis=1)
        if width:
            x = np.clip(x_best + width * np.linspace(-1.0, 1.0, REFINE_POINTS)[:, None], SCAN[0],
                        SCAN[-1])
    score, acc = (np.take_along_axis(v, g, axis=1)[:, 0] for v in (score, acc))
    corners = np.take_along_axis(corners, g[None], axis=2)[:, :, 0]  # (4, 3, n)
    f = np.argmin(score, axis=0)[None]
    return (np.take_along_axis(acc, f, axis=0)[0],
            np.take_along_axis(x_best[:, 0], f, axis=0)[0] * h,
            np.take_along_axis(corners, f[None], axis=1)[:, 0])


def segment_models(t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                   qdd: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Choose the two pieces of every segment and joint (see the module docstring).

    :param t: ``(N,)`` strictly increasing times, ``N >= 2``; :param q, qd: ``(N, 3)``.
    :param qdd: ``(N, 3)`` given accelerations, or ``None`` (the cubic everywhere).
    :return: ``(ts, corners)``: switch times ``tau_s`` ``(N-1, 3)``, s from the segment's
        start (``h`` for one piece), and the accelerations ``alpha_0, L, R, alpha_1``
        ``(4, N-1, 3)``.
    """
    h = np.diff(t)[:, None]
    a2, a3 = hermite_coefficients(t, q, qd)
    end = 2.0 * a2 + 6.0 * a3 * h
    ts = np.broadcast_to(h, a2.shape).copy()
    corners = np.stack([2.0 * a2, end, end, end])
    if qdd is None:
        return ts, corners
    v0, v1, a0, a1 = qd[:-1], qd[1:], qdd[:-1], qdd[1:]
    # the switch model
    da = a0 - a1
    switch = np.divide(v1 - v0 - a1 * h, da, out=np.full(da.shape, -1.0),
                       where=np.abs(da) > 1e-12)
    fits = (switch >= -1e-9 * h) & (switch <= h * (1.0 + 1e-9))
    switch = np.clip(switch, 0.0, h)
    rest = h - switch
    r = q[1:] - (q[:-1] + v0 * h + 0.5 * a0 * switch * switch + a0 * switch * rest
                 + 0.5 * a1 * rest * rest)
    k = 6.0 * r / (h * h)
    mid = k * (1.0 - 2.0 * switch / h)
    switched = np.stack([a0 + k, a0 + mid, a1 + mid, a1 - k])
    peak, _ = piece_peaks(h, v0, v1, ts, corners)
    peak_switch, _ = piece_peaks(h, v0, v1, switch, switched)
    use = fits & (peak_switch < peak)
    ts = np.where(use, switch, ts)
    corners = np.where(use, switched, corners)
    peak = np.where(use, peak_switch, peak)
    # the scanned pieces, only where the cubic and the switch model overshoot the joint's
    # largest given acceleration (the limit of a time-optimal plan), and only if clearly better
    scale_a = np.maximum(np.abs(qdd).max(axis=0), 1e-9)
    scale_v = np.maximum(np.abs(qd).max(axis=0), 1e-9)
    need = peak > (1.0 + PREFER) * scale_a
    if not np.any(need):
        return ts, corners
    seg, joint = np.nonzero(need)
    h_n = h[seg, 0]
    peak_scan, ts_scan, scanned = _scanned(
        h_n, q[seg + 1, joint] - q[seg, joint], v0[seg, joint], v1[seg, joint], a0[seg, joint],
        a1[seg, joint], scale_a[joint], scale_v[joint])
    use = peak_scan < peak[seg, joint] - PREFER * scale_a[joint]
    seg, joint = seg[use], joint[use]
    ts, corners = ts.copy(), corners.copy()
    ts[seg, joint] = ts_scan[use]
    corners[:, seg, joint] = scanned[:, use]
    return ts, corners


def model_peak_speed(t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                     qdd: Optional[np.ndarray] = None, models=None) -> np.ndarray:
    """Largest ``|qd|`` per joint of the reference as interpolated (:func:`segment_models`).

    :param models: the pieces :func:`segment_models` chose, if chosen already.
    :return: ``(3,)`` peak absolute velocity, at the points and between them.
    """
    peak = np.abs(qd).max(axis=0)
    if len(t) < 2:
        return peak
    ts, corners = segment_models(t, q, qd, qdd) if models is None else models
    _, speed = piece_peaks(np.diff(t)[:, None], qd[:-1], qd[1:], ts, corners)
    return np.maximum(peak, speed.max(axis=0))


class Validated(NamedTuple):
    """A trajectory :func:`validate_trajectory` accepted, with its pieces (segment_models)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: Optional[np.ndarray]
    models: Optional[Tuple[np.ndarray, np.ndarray]]


def validate_trajectory(t: ArrayLike, q: ArrayLike, qd: Optional[ArrayLike], lower: np.ndarray,
                        upper: np.ndarray, max_velocity: np.ndarray,
                        velocity_tolerance: float = 0.01, position_tolerance: float = 1e-6,
                        qdd: Optional[ArrayLike] = None):
    """Check a trajectory and return it as arrays, or say why it is refused.

    :param t: ``(N,)`` absolute times, s, strictly increasing, ``N >= 1``.
    :param q: ``(N, 3)`` joint positions (rad, rad, m).
    :param qd: ``(N, 3)`` joint velocities or ``None`` (finite differences, zero at the ends).
    :param lower, upper: ``(3,)`` joint position limits.
    :param max_velocity: ``(3,)`` joint velocity limits.
    :param velocity_tolerance: relative slack on the velocity limit (rounding of sampled plans).
    :param position_tolerance: absolute slack on the position limits.
    :param qdd: ``(N, 3)`` joint accelerations or ``None`` (Hermite derivative).
    :return: :class:`Validated`: ``(t, q, qd, qdd)`` float arrays (``qdd`` may be ``None``)
        and the pieces chosen between the points (``None`` for one point), so
        ``HermiteReference(*validated)`` does not choose them again.
    :raises TrajectoryError: bad shape, non-finite values, non-increasing times, a position
        outside the limits, or a velocity (at a point or between points, as
        :class:`HermiteReference` interpolates them) above the limit.
    """
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise TrajectoryError('times are not numeric') from None
    if t.ndim != 1 or len(t) == 0:
        raise TrajectoryError(f'times must be a non-empty (N,) array, got shape {np.shape(t)}')
    n = len(t)
    t = _array(t, 'times', (n,))
    q = _array(q, 'positions', (n, 3))
    if n > 1 and np.any(np.diff(t) <= 0.0):
        bad = int(np.argmax(np.diff(t) <= 0.0)) + 1
        raise TrajectoryError(f'times must increase strictly; point {bad} is at {t[bad]:.6f} s, '
                              f'not after {t[bad - 1]:.6f} s')
    lo, hi = lower - position_tolerance, upper + position_tolerance
    out = (q < lo) | (q > hi)
    if np.any(out):
        i, j = (int(v) for v in np.argwhere(out)[0])
        raise TrajectoryError(f'position of joint {j + 1} at point {i} is {q[i, j]:.6f}, outside '
                              f'the limits [{lower[j]:.6f}, {upper[j]:.6f}]')
    if qd is None:
        qd = np.zeros_like(q)
        if n > 2:
            qd[1:-1] = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]
    else:
        qd = _array(qd, 'velocities', (n, 3))
    if qdd is not None:
        qdd = _array(qdd, 'accelerations', (n, 3))
    models = segment_models(t, q, qd, qdd) if n > 1 else None
    peak = model_peak_speed(t, q, qd, qdd, models)
    over = peak > max_velocity * (1.0 + velocity_tolerance)
    if np.any(over):
        j = int(np.argmax(over))
        raise TrajectoryError(f'velocity of joint {j + 1} reaches {peak[j]:.4f}, above the limit '
                              f'{max_velocity[j]:.4f} (interpolated between the points)')
    return Validated(t, q, qd, qdd, models)


class HermiteReference:
    """A validated joint trajectory, interpolated between its points (one arm, 3 joints).

    Per segment and joint two pieces with linear accelerations, chosen by
    :func:`segment_models`: the cubic Hermite spline of positions and velocities without
    accelerations; with them, the cubic, the switch model or scanned pieces, for the lowest
    peak acceleration (the module docstring says how). :meth:`sample` evaluates one of the two
    cubics per joint in plain floats (one bisection, no numpy until the result).

    Before ``t[0]`` and after ``t[-1]`` it returns the first / last point at rest; the
    simulator holds its own position before the start (see ``CellSim.execute``).

    :param t: ``(N,)`` increasing absolute times, s.
    :param q, qd: ``(N, 3)`` positions and velocities.
    :param qdd: ``(N, 3)`` accelerations, or ``None`` to use the Hermite derivative.
    """

    def __init__(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                 qdd: Optional[np.ndarray] = None, models=None):
        """Choose the pieces (unless ``models`` has them) and keep their coefficients."""
        self.t, self.q, self.qd, self.qdd = t, q, qd, qdd
        self.start, self.end = float(t[0]), float(t[-1])
        self._times = t.tolist()
        self._pieces = []
        if len(t) > 1:
            ts, corners = segment_models(t, q, qd, qdd) if models is None else models
            beta0, beta1 = piece_slopes(np.diff(t)[:, None], ts, corners)
            # per segment and joint: tau_s, then (value, rate, half the acceleration, a sixth
            # of the jerk) of the piece from point i in tau and of the one to i + 1 in tau - h
            before = np.stack([q[:-1], qd[:-1], 0.5 * corners[0], beta0 / 6.0], axis=-1)
            after = np.stack([q[1:], qd[1:], 0.5 * corners[3], beta1 / 6.0], axis=-1)
            self._pieces = [[(s, tuple(b), tuple(a)) for s, b, a in zip(*seg)]
                            for seg in zip(ts.tolist(), before.tolist(), after.tolist())]
        self._zero = np.zeros(3)

    def sample(self, time: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the reference ``(q, qd, qdd)``, each ``(3,)``, at absolute time ``time``."""
        if time <= self.start:
            return self.q[0], self._zero, self._zero
        if time >= self.end:
            return self.q[-1], self._zero, self._zero
        times = self._times
        i = bisect_right(times, time) - 1
        tau = time - times[i]
        pos, vel, acc = [], [], []
        for switch, before, after in self._pieces[i]:
            if tau < switch:
                x = tau
                c0, c1, c2, c3 = before
            else:
                x = time - times[i + 1]
                c0, c1, c2, c3 = after
            pos.append(c0 + x * (c1 + x * (c2 + x * c3)))
            vel.append(c1 + x * (2.0 * c2 + 3.0 * c3 * x))
            acc.append(2.0 * c2 + 6.0 * c3 * x)
        return np.array(pos), np.array(vel), np.array(acc)
