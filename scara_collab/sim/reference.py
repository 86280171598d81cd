"""Joint references for the simulator: validated trajectories, interpolated between points.

A trajectory arrives as absolute times ``t`` ``(N,)`` and joint positions ``q`` ``(N, 3)``,
optionally with velocities and accelerations. Between two points the reference is the cubic
Hermite polynomial through both positions with both velocities, written per segment ``i`` in
``tau = t - t_i`` (``h = t_{i+1} - t_i``, ``dq = q_{i+1} - q_i``, ``m = qd``)::

    q(tau)  = q_i + m_i tau + a2 tau^2 + a3 tau^3
    a2 = (3 dq / h - 2 m_i - m_{i+1}) / h,    a3 = (m_i + m_{i+1} - 2 dq / h) / h^2

so position and velocity are continuous at every point and the acceleration ``2 a2 + 6 a3 tau``
is its exact derivative (given accelerations, if any, are interpolated linearly instead). The
velocity is quadratic in ``tau``: its peak inside a segment is at ``tau* = -a2 / (3 a3)``, which
is how :func:`validate_trajectory` checks the velocity limit *between* the points, not only at
them. Without velocities, interior points get central finite differences and both ends zero
(the arm starts from a hold and ends in a hold).

**Switching accelerations.** A time-optimal plan is bang-bang: its acceleration jumps (from
``+a_max`` to ``-a_max``, say) between two samples. No cubic through the two ends' positions
and velocities can follow that: its acceleration, linear in ``tau``, overshoots the planned one
by up to 1.5x. So where the accelerations are given, a joint whose two end accelerations
``a_i``, ``a_{i+1}`` differ is modelled as holding ``a_i`` until a switch time ``tau_s`` and
``a_{i+1}`` after it, with ``tau_s`` the one that matches both end velocities::

    tau_s = (m_{i+1} - m_i - a_{i+1} h) / (a_i - a_{i+1})

plus the smoothstep ``r (3 x^2 - 2 x^3)``, ``x = tau / h``, that takes up the position left
over, ``r`` (zero for a plan that really switched once; position and velocity stay continuous
at both ends). This *switch model* is used per segment and joint when ``tau_s`` lies in the
segment and its acceleration bound ``max(|a_i|, |a_{i+1}|) + 6 |r| / h^2`` is below the cubic's
peak acceleration; otherwise the cubic is. The acceleration it returns is its exact derivative.

No PyBullet here: plain numpy, tested alone.
"""
from bisect import bisect_right
from typing import Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike


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


def switch_model(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                 a2: np.ndarray, a3: np.ndarray):
    """Fit the switch model (see the module docstring) to every segment and joint.

    :param a2, a3: the cubic's coefficients (:func:`hermite_coefficients`), to compare with.

    :return: ``(use, ts, r)``, each ``(N-1, 3)``: where the switch model replaces the cubic,
        its switch time ``tau_s`` (s from the segment's start) and its position residual ``r``
        (both 0 where it is not used).
    """
    h = np.diff(t)[:, None]
    v0, v1, a0, a1 = qd[:-1], qd[1:], qdd[:-1], qdd[1:]
    da = a0 - a1
    with np.errstate(divide='ignore', invalid='ignore'):
        ts = np.where(np.abs(da) > 1e-12, (v1 - v0 - a1 * h) / np.where(da != 0.0, da, 1.0),
                      -1.0)
    fits = (ts >= -1e-9 * h) & (ts <= h * (1.0 + 1e-9))
    ts = np.clip(ts, 0.0, h)
    rest = h - ts
    reach = q[:-1] + v0 * h + 0.5 * a0 * ts * ts + a0 * ts * rest + 0.5 * a1 * rest * rest
    r = q[1:] - reach
    cubic_peak = np.maximum(np.abs(2.0 * a2), np.abs(2.0 * a2 + 6.0 * a3 * h))
    switch_peak = np.maximum(np.abs(a0), np.abs(a1)) + 6.0 * np.abs(r) / (h * h)
    use = fits & (switch_peak < cubic_peak)
    return use, np.where(use, ts, 0.0), np.where(use, r, 0.0)


def model_peak_speed(t: np.ndarray, qd: np.ndarray, a2: np.ndarray, a3: np.ndarray,
                     qdd: np.ndarray, use, ts, r) -> np.ndarray:
    """Largest ``|qd|`` per joint of the reference as interpolated (cubic or switch model).

    :return: ``(3,)`` peak absolute velocity.
    """
    peak = peak_speed(t, qd, a2, a3, exclude=use)
    if not np.any(use):
        return peak
    h = np.diff(t)[:, None]
    vs = qd[:-1] + qdd[:-1] * ts  # the velocity at the switch: the piecewise-linear peak
    switch = np.maximum(np.maximum(np.abs(qd[:-1]), np.abs(qd[1:])), np.abs(vs)) \
        + 1.5 * np.abs(r) / h
    return np.maximum(peak, np.where(use, switch, 0.0).max(axis=0, initial=0.0))


def peak_speed(t: np.ndarray, qd: np.ndarray, a2: np.ndarray, a3: np.ndarray,
               exclude: Optional[np.ndarray] = None) -> np.ndarray:
    """Largest ``|qd|`` of the Hermite reference per joint, points and segment interiors.

    :param exclude: ``(N-1, 3)`` segments and joints whose interior is not checked.
    :return: ``(3,)`` peak absolute velocity.
    """
    h = np.diff(t)[:, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        ts = np.where(a3 != 0.0, -a2 / (3.0 * np.where(a3 != 0.0, a3, 1.0)), -1.0)
    inside = (ts > 0.0) & (ts < h)
    if exclude is not None:  # segments interpolated otherwise (the switch model)
        inside &= ~exclude
    ts = np.where(inside, ts, 0.0)
    interior = np.where(inside, np.abs(qd[:-1] + 2.0 * a2 * ts + 3.0 * a3 * ts * ts), 0.0)
    return np.maximum(np.abs(qd).max(axis=0), interior.max(axis=0, initial=0.0))


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
    :return: ``(t, q, qd, qdd)`` float arrays (``qdd`` may be ``None``).
    :raises TrajectoryError: bad shape, non-finite values, non-increasing times, a position
        outside the limits, or a velocity (at a point or between points) above the limit.
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
    peak = np.abs(qd).max(axis=0)
    if n > 1:
        a2, a3 = hermite_coefficients(t, q, qd)
        if qdd is None:
            peak = peak_speed(t, qd, a2, a3)
        else:
            peak = model_peak_speed(t, qd, a2, a3, qdd, *switch_model(t, q, qd, qdd, a2, a3))
    over = peak > max_velocity * (1.0 + velocity_tolerance)
    if np.any(over):
        j = int(np.argmax(over))
        raise TrajectoryError(f'velocity of joint {j + 1} reaches {peak[j]:.4f}, above the limit '
                              f'{max_velocity[j]:.4f} (interpolated between the points)')
    return t, q, qd, qdd


class HermiteReference:
    """A validated joint trajectory, interpolated between its points (one arm, 3 joints).

    The cubic Hermite spline of positions and velocities; where accelerations are given, the
    switch model for segments whose acceleration jumps (see the module docstring), and the
    given accelerations interpolated linearly elsewhere.

    Before ``t[0]`` and after ``t[-1]`` it returns the first / last point at rest; the
    simulator holds its own position before the start (see ``CellSim.execute``).

    :param t: ``(N,)`` increasing absolute times, s.
    :param q, qd: ``(N, 3)`` positions and velocities.
    :param qdd: ``(N, 3)`` accelerations, or ``None`` to use the Hermite derivative.
    """

    def __init__(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray,
                 qdd: Optional[np.ndarray] = None):
        """Precompute the cubic coefficients per segment (and, with ``qdd``, the switch model)."""
        self.t, self.q, self.qd, self.qdd = t, q, qd, qdd
        self.start, self.end = float(t[0]), float(t[-1])
        self._times = t.tolist()
        n = len(t)
        # per segment, rows (1, tau, tau^2, tau^3) -> one (3, 4) @ (4, 3) product per sample
        self._coef = np.zeros((max(n - 1, 1), 4, 3))
        self._split = [False] * max(n - 1, 1)
        if n > 1:
            a2, a3 = hermite_coefficients(t, q, qd)
            self._coef[:, 0], self._coef[:, 1] = q[:-1], qd[:-1]
            self._coef[:, 2], self._coef[:, 3] = a2, a3
            if qdd is not None:
                use, ts, self._r = switch_model(t, q, qd, qdd, a2, a3)
                # before the switch: constant acceleration a_i; after it (rows value, rate,
                # half the acceleration in u = tau - tau_s): a_{i+1}
                self._coef[:, 2] = np.where(use, 0.5 * qdd[:-1], a2)
                self._coef[:, 3] = np.where(use, 0.0, a3)
                qs = q[:-1] + qd[:-1] * ts + 0.5 * qdd[:-1] * ts * ts
                self._after = np.stack([qs, qd[:-1] + qdd[:-1] * ts, 0.5 * qdd[1:]], axis=1)
                # joints without a switch never reach theirs: one segment length beyond
                self._ts = np.where(use, ts, 2.0 * np.diff(t)[:, None])
                self._use = use
                self._split = use.any(axis=1).tolist()
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
        tau2 = tau * tau
        basis = np.array(((1.0, tau, tau2, tau2 * tau),
                          (0.0, 1.0, 2.0 * tau, 3.0 * tau2),
                          (0.0, 0.0, 2.0, 6.0 * tau)))
        q, qd, qdd = basis @ self._coef[i]
        if self.qdd is None:
            return q, qd, qdd
        h = times[i + 1] - times[i]
        x = tau / h
        linear = (1.0 - x) * self.qdd[i] + x * self.qdd[i + 1]
        if not self._split[i]:
            return q, qd, linear
        u = tau - self._ts[i]
        after = u >= 0.0
        b, r = self._after[i], self._r[i]
        q = np.where(after, b[0] + b[1] * u + b[2] * u * u, q) + r * (x * x * (3.0 - 2.0 * x))
        qd = np.where(after, b[1] + 2.0 * b[2] * u, qd) + r * (6.0 * x * (1.0 - x) / h)
        switched = np.where(after, 2.0 * b[2], qdd) + r * ((6.0 - 12.0 * x) / (h * h))
        return q, qd, np.where(self._use[i], switched, linear)
