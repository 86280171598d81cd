"""Arm-to-arm collision geometry: exact segment distance, capsule arms, trajectory conflicts.

Each arm is three capsules (link 1, link 2, the quill). Two arms are apart by the smallest
capsule *surface* distance over the 3 x 3 capsule pairs: the exact distance between the capsule
axis segments minus both radii (negative = the capsules overlap). All functions are stateless;
a function that takes N states takes an (N, ...) array.

The formulas (the segment distance, the capsules' forward kinematics) are written once, on
``(x, y, z)`` tuples of coordinates, over a small "ops" namespace, as
:func:`scara_collab.core.kinematics.ik` is: evaluated with the ``math`` module and plain
floats for one segment pair or one state pair (a few microseconds, no numpy per-call
overhead), with numpy arrays for N (vectorised, broadcasting). The single case is the same
code, not a copy.

The segment distance is the clamped closed-form solution of Ericson, *Real-Time Collision
Detection* (2005), section 5.1.9, written branch-free (``where``), with the line-line
parameter taken from cross products so nearly parallel segments lose no accuracy. Unlike an
endpoint-only check (the four endpoint-to-segment distances) it is right for segments that
cross, e.g. the two diagonals of a unit square::

    >>> d, s, t = segment_distance([0, 0, 0], [1, 1, 0], [0, 1, 0], [1, 0, 0])
    >>> float(d), float(s), float(t)
    (0.0, 0.5, 0.5)

Conflict resolution gives the leader (arm a) priority: the follower (arm b) is started late by
the smallest delay that keeps the arms at least ``margin`` apart over both trajectories
(:func:`smallest_safe_delay`). The margin is always a parameter; the cell's default is
``CellModel.safety_margin``.

Over trajectories, the 9 capsule pairs at every time of a fine grid (thousands of states) are
prefiltered: the gap between the axis-aligned boxes around two capsule axes, less both radii
and a rounding slack, is a cheap lower bound of their surface distance. A safety check
computes the exact distance only of the pairs whose bound is below the margin; the minimum,
only of those whose bound does not exceed the exact distance at the state with the smallest
bound. Both give the full computation's results, bit for bit.
"""
import math
from typing import Callable, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core.model import ArmModel
from scara_collab.core.trajectory import interp_rows

#: A squared segment length at or below this (m^2) is treated as a point.
_DEGENERATE_SQ = 1e-24
#: Segments whose squared sine of the angle between them is at or below this are parallel.
#: Any s in [0, 1] is then within (segment length * 1e-15) of optimal, so the value only
#: guards the division.
_PARALLEL_SIN_SQ = 1e-30
#: Default largest spacing of the common time grid of :func:`trajectory_min_distance`, s.
MAX_TIME_STEP = 0.005
#: Taken off the cheap capsule-pair lower bounds, m, so that rounding never lifts a bound
#: above the exact distance (whose rounding error is ~1e-15 m at cell scale).
_BOUND_SLACK = 1e-9
#: Capsule indices (i of a, j of b) of the 3 x 3 pairs, in row-major order.
_ALL_PAIRS = (np.repeat(np.arange(3), 3), np.tile(np.arange(3), 3))


class _ScalarOps:
    """``math`` versions of the few operations the formulas use (plain floats)."""

    sqrt = staticmethod(math.sqrt)
    cos = staticmethod(math.cos)
    sin = staticmethod(math.sin)

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def clip01(x):
        return 0.0 if x < 0.0 else 1.0 if x > 1.0 else x


class _VectorOps:
    """numpy versions of the same operations (arrays that broadcast)."""

    sqrt = staticmethod(np.sqrt)
    cos = staticmethod(np.cos)
    sin = staticmethod(np.sin)
    where = staticmethod(np.where)

    @staticmethod
    def clip01(x):
        return np.minimum(np.maximum(x, 0.0), 1.0)


def _segments(ops, p0, p1, q0, q1):
    """Return ``(dist, s, t)`` of :func:`segment_distance`, on (x, y, z) coordinate tuples.

    The one formula: with :class:`_ScalarOps` the coordinates are floats (one pair), with
    :class:`_VectorOps` arrays that broadcast together (N pairs). Written out per coordinate
    (no helper calls) so that one pair costs a few microseconds.
    """
    where, clip01 = ops.where, ops.clip01
    (p0x, p0y, p0z), (p1x, p1y, p1z), (q0x, q0y, q0z), (q1x, q1y, q1z) = p0, p1, q0, q1
    d1x, d1y, d1z = p1x - p0x, p1y - p0y, p1z - p0z
    d2x, d2y, d2z = q1x - q0x, q1y - q0y, q1z - q0z
    rx, ry, rz = p0x - q0x, p0y - q0y, p0z - q0z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    b = d1x * d2x + d1y * d2y + d1z * d2z
    c = d1x * rx + d1y * ry + d1z * rz
    f = d2x * rx + d2y * ry + d2z * rz
    point_p = a <= _DEGENERATE_SQ
    point_q = e <= _DEGENERATE_SQ
    safe_a = where(point_p, 1.0, a)
    safe_e = where(point_q, 1.0, e)
    # Closest point of the infinite lines, clamped (s = 0 for parallel lines: any s will do):
    # s = (-r x d2) . n / |n|^2 with n = d1 x d2. Through cross products rather than
    # a e - b^2 and b f - c e: those cancel catastrophically for nearly parallel segments,
    # these stay accurate to rounding at any angle.
    nx, ny, nz = d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x
    mx, my, mz = d2y * rz - d2z * ry, d2z * rx - d2x * rz, d2x * ry - d2y * rx  # -r x d2
    denom = nx * nx + ny * ny + nz * nz
    parallel = denom <= _PARALLEL_SIN_SQ * a * e
    s_line = clip01((mx * nx + my * ny + mz * nz) / where(parallel, 1.0, denom))
    s = where(point_q, clip01(-c / safe_a), where(parallel, 0.0, s_line))
    s = where(point_p, 0.0, s)
    # The t closest to that s; if it leaves [0, 1], clamp it and recompute s for the clamped t.
    t_free = where(point_q, 0.0, (b * s + f) / safe_e)
    t = clip01(t_free)
    s = where(point_p | (t == t_free), s, clip01((b * t - c) / safe_a))
    gx, gy, gz = rx + s * d1x - t * d2x, ry + s * d1y - t * d2y, rz + s * d1z - t * d2z
    return ops.sqrt(gx * gx + gy * gy + gz * gz), s, t


def _coords(x: np.ndarray):
    """Return the (x, y, z) tuple of the last axis of an (..., 3) array."""
    return x[..., 0], x[..., 1], x[..., 2]


def segment_distance(p0: ArrayLike, p1: ArrayLike, q0: ArrayLike,
                     q1: ArrayLike) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact minimum distance between the 3D segments ``p0-p1`` and ``q0-q1``.

    The closest points are ``p0 + s (p1 - p0)`` and ``q0 + t (q1 - q0)``. Crossing, parallel,
    collinear (overlapping or not) and zero-length segments are all handled; for parallel
    segments, whose closest points are not unique, one valid pair is returned. One pair of
    segments is computed on plain floats, N on arrays, by the same formula.

    :param p0: (..., 3) start of the first segment, m.
    :param p1: (..., 3) end of the first segment, m.
    :param q0: (..., 3) start of the second segment, m.
    :param q1: (..., 3) end of the second segment, m. All four broadcast together.
    :return: ``(dist, s, t)``, each of the broadcast shape without the last axis: the distance
        (m, >= 0) and the closest-point parameters in [0, 1].

    Example (skew segments 0.5 m apart in z, crossing in plan view)::

        >>> d, s, t = segment_distance([0, 0, 0], [2, 0, 0], [1, -1, 0.5], [1, 1, 0.5])
        >>> float(d), float(s), float(t)
        (0.5, 0.5, 0.5)
    """
    points = [np.asarray(v, dtype=float) for v in (p0, p1, q0, q1)]
    if all(v.shape == (3,) for v in points):
        return tuple(np.float64(x) for x in _segments(
            _ScalarOps, *(tuple(v.tolist()) for v in points)))
    return _segments(_VectorOps, *(_coords(v) for v in points))


def capsule_distance(p0: ArrayLike, p1: ArrayLike, radius_p: ArrayLike, q0: ArrayLike,
                     q1: ArrayLike, radius_q: ArrayLike) -> np.ndarray:
    """Surface distance between two capsules (segment distance minus both radii).

    :param p0: (..., 3) first capsule's axis start, m.
    :param p1: (..., 3) first capsule's axis end, m.
    :param radius_p: (...) first capsule's radius, m.
    :param q0: (..., 3) second capsule's axis start, m.
    :param q1: (..., 3) second capsule's axis end, m.
    :param radius_q: (...) second capsule's radius, m.
    :return: (...) surface distance, m; negative = the capsules overlap by that much.

    Two capsules of radius 0.1 m whose axes cross 0.15 m apart overlap by 5 cm:

    >>> d = capsule_distance([0, 0, 0], [1, 0, 0], 0.1, [0.5, -1, 0.15], [0.5, 1, 0.15], 0.1)
    >>> round(float(d), 6)
    -0.05
    """
    dist, _, _ = segment_distance(p0, p1, q0, q1)
    return dist - np.asarray(radius_p, dtype=float) - np.asarray(radius_q, dtype=float)


def _radii(arm: ArmModel) -> Tuple[float, float, float]:
    return (arm.link_radius, arm.link_radius, arm.quill_radius)


def _capsules(ops, arm: ArmModel, theta1, theta2, d3):
    """Return the capsule axes of ``arm`` in ``world``: ``[(start, end)] * 3``, (x, y, z) tuples.

    The one forward kinematics of the capsules (see :func:`arm_capsules` for the layout), on
    floats (:class:`_ScalarOps`, one state) or arrays (:class:`_VectorOps`, N states); the
    coordinates that do not depend on the state are floats either way. It stands in for
    ``kinematics.arm_points`` (shoulder, elbow, tool tip) so this module does not depend on it.
    """
    h1 = float(arm.shoulder_height)
    h2 = h1 + arm.elbow_rise
    elbow_x, elbow_y = arm.l1 * ops.cos(theta1), arm.l1 * ops.sin(theta1)
    tool_x = elbow_x + arm.l2 * ops.cos(theta1 + theta2)
    tool_y = elbow_y + arm.l2 * ops.sin(theta1 + theta2)
    tip_z = h2 - d3
    (r00, r01, r02, o0), (r10, r11, r12, o1), (r20, r21, r22, o2) = arm.base[:3].tolist()

    def world(x, y, z):
        return (r00 * x + r01 * y + r02 * z + o0, r10 * x + r11 * y + r12 * z + o1,
                r20 * x + r21 * y + r22 * z + o2)

    return [(world(0.0, 0.0, h1), world(elbow_x, elbow_y, h1)),
            (world(elbow_x, elbow_y, h2), world(tool_x, tool_y, h2)),
            (world(tool_x, tool_y, tip_z), world(tool_x, tool_y, tip_z + arm.quill_length))]


def _vector_capsules(arm: ArmModel, q: ArrayLike):
    """Return :func:`_capsules` of (..., 3) states as arrays: ``(start, end)``, (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (3,):
        raise ValueError(f'joint states must have shape (..., 3), got {q.shape}')
    caps = _capsules(_VectorOps, arm, *_coords(q))
    shape = q.shape[:-1]
    start, end = (np.stack([np.stack([np.broadcast_to(c, shape) for c in cap[k]], -1)
                            for cap in caps], -2) for k in (0, 1))
    return start, end


def arm_capsules(arm: ArmModel, q: ArrayLike) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame capsules of one arm: link 1, link 2 and the quill, in that order.

    - link 1: shoulder (base + ``shoulder_height`` along the base z) to the elbow, at the
      shoulder height, radius ``link_radius``;
    - link 2: elbow to the quill axis, ``elbow_rise`` above link 1, radius ``link_radius``;
    - quill: from the tool tip (``d3`` below link 2) up ``quill_length`` along the base z,
      radius ``quill_radius``.

    Capsules are conservative: their round ends stick out one radius past the URDF cylinders.

    :param arm: the arm model.
    :param q: (..., 3) joint states ``(theta1 rad, theta2 rad, d3 m)``.
    :return: ``(start, end, radii)``: start and end points (..., 3, 3) in ``world`` (m), one row
        per capsule, and the capsule radii (3,) in m.
    """
    start, end = _vector_capsules(arm, q)
    return start, end, np.array(_radii(arm))


def arm_pair_distances(arm_a: ArmModel, q_a: ArrayLike, arm_b: ArmModel,
                       q_b: ArrayLike) -> np.ndarray:
    """Surface distance of every capsule of arm a to every capsule of arm b.

    One state of each arm (the collision monitor's 100 Hz check, single-state queries) is
    computed on plain floats, N on arrays, by the same formulas.

    :param arm_a: the first arm.
    :param q_a: (..., 3) its joint states.
    :param arm_b: the second arm.
    :param q_b: (..., 3) its joint states; broadcasts with ``q_a`` (pairs of states).
    :return: (..., 3, 3) distances, m; entry ``[..., i, j]`` is capsule i of a (link 1, link 2,
        quill) to capsule j of b; negative = overlap.
    """
    if np.shape(q_a) == (3,) and np.shape(q_b) == (3,):
        caps_a = _capsules(_ScalarOps, arm_a, *np.asarray(q_a, dtype=float).tolist())
        caps_b = _capsules(_ScalarOps, arm_b, *np.asarray(q_b, dtype=float).tolist())
        return np.array([[_segments(_ScalarOps, p0, p1, q0, q1)[0] - rp - rq
                          for (q0, q1), rq in zip(caps_b, _radii(arm_b))]
                         for (p0, p1), rp in zip(caps_a, _radii(arm_a))])
    start_a, end_a = _vector_capsules(arm_a, q_a)
    start_b, end_b = _vector_capsules(arm_b, q_b)
    dist, _, _ = _segments(_VectorOps, _coords(start_a[..., :, None, :]),
                           _coords(end_a[..., :, None, :]), _coords(start_b[..., None, :, :]),
                           _coords(end_b[..., None, :, :]))
    return dist - np.array(_radii(arm_a))[:, None] - np.array(_radii(arm_b))[None, :]


def closest_points(arm_a: ArmModel, q_a: ArrayLike, arm_b: ArmModel, q_b: ArrayLike):
    """Return the closest capsule pair of two arms at one state each, with its axis points.

    :param arm_a: the first arm.
    :param q_a: (3,) its joint state.
    :param arm_b: the second arm.
    :param q_b: (3,) its joint state.
    :return: ``(pairs, distance, p, q)``: the (3, 3) capsule surface distances of
        :func:`arm_pair_distances`, the smallest of them (m), and the closest points (3,) of
        that pair's axes on arm a and arm b.
    """
    pairs = arm_pair_distances(arm_a, q_a, arm_b, q_b)
    i, j = np.unravel_index(int(np.argmin(pairs)), pairs.shape)
    start_a, end_a, _ = arm_capsules(arm_a, q_a)
    start_b, end_b, _ = arm_capsules(arm_b, q_b)
    _, s, t = segment_distance(start_a[i], end_a[i], start_b[j], end_b[j])
    p = start_a[i] + float(s) * (end_a[i] - start_a[i])
    q = start_b[j] + float(t) * (end_b[j] - start_b[j])
    return pairs, float(pairs[i, j]), p, q


def arm_distance(arm_a: ArmModel, q_a: ArrayLike, arm_b: ArmModel, q_b: ArrayLike) -> np.ndarray:
    """Smallest capsule surface distance between two arms.

    :param arm_a: the first arm.
    :param q_a: (..., 3) its joint states.
    :param arm_b: the second arm.
    :param q_b: (..., 3) its joint states; broadcasts with ``q_a`` (pairs of states at the same
        time).
    :return: (...) distance, m; negative = penetration.
    """
    return arm_pair_distances(arm_a, q_a, arm_b, q_b).min(axis=(-2, -1))


def _check_trajectory(t: ArrayLike, q: ArrayLike, name: str) -> Tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if t.ndim != 1 or t.size == 0 or q.shape != (t.size, 3):
        raise ValueError(f'trajectory {name}: need t (N,) and q (N, 3) with N >= 1, '
                         f'got {t.shape} and {q.shape}')
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise ValueError(f'trajectory {name}: non-finite times or positions')
    if np.any(np.diff(t) <= 0.0):
        raise ValueError(f'trajectory {name}: times must be strictly increasing')
    return t, q


def _grid_states(t_a: np.ndarray, q_a: np.ndarray, t_b: np.ndarray, q_b: np.ndarray,
                 start_b: float, max_step: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the time grid of :func:`trajectory_min_distance` and both arms' states on it."""
    if not max_step > 0.0:
        raise ValueError(f'max_step must be > 0, got {max_step}')
    t_b = t_b + float(start_b)
    t0 = min(t_a[0], t_b[0])
    t1 = max(t_a[-1], t_b[-1])
    fine = np.linspace(t0, t1, int(np.ceil((t1 - t0) / max_step)) + 1)
    times = np.unique(np.concatenate([t_a, t_b, fine]))
    return times, interp_rows(times, t_a, q_a), interp_rows(times, t_b, q_b)


def _axis_boxes(arm: ArmModel, q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes around the capsule axes of ``arm`` at N joint states, in ``world``.

    :param q: (N, 3) joint states.
    :return: ``(lo, hi)``: the boxes' low and high corners (3, 3, N), m, indexed by coordinate,
        capsule (link 1, link 2, quill) and state.
    """
    theta1, theta2, d3 = q[:, 0], q[:, 1], q[:, 2]
    elbow_x = arm.l1 * np.cos(theta1)
    elbow_y = arm.l1 * np.sin(theta1)
    tool_x = elbow_x + arm.l2 * np.cos(theta1 + theta2)
    tool_y = elbow_y + arm.l2 * np.sin(theta1 + theta2)
    h1 = arm.shoulder_height
    h2 = h1 + arm.elbow_rise
    tip_z = h2 - d3
    lo = np.empty((3, 3, len(q)))
    hi = np.empty_like(lo)
    for c, ((rx, ry, rz), oc) in enumerate(zip(arm.base[:3, :3], arm.base[:3, 3])):
        # World coordinate c of the elbow and quill axes at base height 0, then the ends.
        elbow = rx * elbow_x + ry * elbow_y + oc
        tool = rx * tool_x + ry * tool_y + oc
        ends = ((oc + rz * h1, elbow + rz * h1),  # link 1: shoulder to elbow
                (elbow + rz * h2, tool + rz * h2),  # link 2: elbow to the quill axis
                (tool + rz * tip_z, None))  # quill: tip, then quill_length along base z
        for k, (start, end) in enumerate(ends):
            if end is None:
                np.add(start, min(0.0, rz * arm.quill_length), out=lo[c, k])
                np.add(start, max(0.0, rz * arm.quill_length), out=hi[c, k])
            else:
                np.minimum(start, end, out=lo[c, k])
                np.maximum(start, end, out=hi[c, k])
    return lo, hi


def _pair_bounds(arm_a: ArmModel, q_a: np.ndarray, arm_b: ArmModel,
                 q_b: np.ndarray) -> np.ndarray:
    """Cheap lower bounds of the capsule surface distances of two arms at N state pairs.

    Two segments are at least as far apart as their :func:`_axis_boxes` (the norm of the gaps
    between the boxes' extents along x, y and z); that less both capsule radii and
    :data:`_BOUND_SLACK` cannot exceed the exact :func:`arm_pair_distances` entry, rounding
    included.

    :return: (3, 3, N) bounds, m, indexed by capsule of a, capsule of b and state pair.
    """
    lo_a, hi_a = _axis_boxes(arm_a, q_a)
    lo_b, hi_b = _axis_boxes(arm_b, q_b)
    gap_sq = np.zeros((3, 3, len(q_a)))
    gap = np.empty_like(gap_sq)
    other = np.empty_like(gap_sq)
    for c in range(3):  # gap along c: how far b's box starts above a's, or a's above b's
        np.subtract(lo_b[c, None], hi_a[c, :, None], out=gap)
        np.subtract(lo_a[c, :, None], hi_b[c, None], out=other)
        np.maximum(gap, other, out=gap)
        np.maximum(gap, 0.0, out=gap)
        gap_sq += np.square(gap, out=gap)
    radii_a, radii_b = np.array(_radii(arm_a)), np.array(_radii(arm_b))
    lower = np.sqrt(gap_sq, out=gap_sq)
    lower -= (radii_a[:, None] + radii_b[None, :] + _BOUND_SLACK)[:, :, None]
    return lower


def _exact_pairs(arm_a: ArmModel, q_a: np.ndarray, arm_b: ArmModel, q_b: np.ndarray,
                 i: np.ndarray, j: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Return the :func:`arm_pair_distances` entries ``[n, i, j]`` (K,) of N state pairs.

    Only the states in ``n`` are turned into capsules. Every step works per state (capsule
    pair), so the values are those of the full (N, 3, 3) computation, bit for bit.
    """
    rows, n = np.unique(n, return_inverse=True)
    start_a, end_a = _vector_capsules(arm_a, q_a[rows])
    start_b, end_b = _vector_capsules(arm_b, q_b[rows])
    dist, _, _ = _segments(_VectorOps, _coords(start_a[n, i]), _coords(end_a[n, i]),
                           _coords(start_b[n, j]), _coords(end_b[n, j]))
    return dist - np.array(_radii(arm_a))[i] - np.array(_radii(arm_b))[j]


def _grid_min_distance(arm_a: ArmModel, q_a: np.ndarray, arm_b: ArmModel,
                       q_b: np.ndarray) -> Tuple[float, int]:
    """Return the smallest :func:`arm_distance` over N state pairs and its first index.

    Exact: the exact distance ``best`` of the state pair with the smallest lower bound bounds
    the minimum from above, and only capsule pairs whose lower bound is at most ``best`` can
    reach (or tie with) it, so only those are computed. Every other pair is farther than the
    minimum: a state's minimum over its computed pairs is its true distance wherever that is
    the minimum, and larger elsewhere.
    """
    lower = _pair_bounds(arm_a, q_a, arm_b, q_b)
    n0 = int(np.argmin(lower)) % lower.shape[-1]
    i, j = _ALL_PAIRS
    best = _exact_pairs(arm_a, q_a, arm_b, q_b, i, j, np.full(9, n0)).min()
    i, j, n = np.nonzero(lower <= best)
    pairs = np.full(lower.shape, np.inf)
    pairs[i, j, n] = _exact_pairs(arm_a, q_a, arm_b, q_b, i, j, n)
    dist = pairs.min(axis=(0, 1))
    k = int(np.argmin(dist))
    return float(dist[k]), k


def _grid_safe(arm_a: ArmModel, q_a: np.ndarray, arm_b: ArmModel, q_b: np.ndarray,
               margin: float) -> bool:
    """Return whether :func:`arm_distance` >= ``margin`` at all N state pairs.

    Only the capsule pairs whose lower bound is below the margin are computed exactly, the one
    with the smallest bound first (when unsafe, it usually is the culprit).
    """
    lower = _pair_bounds(arm_a, q_a, arm_b, q_b)
    i, j, n = np.nonzero(~(lower >= margin))  # all pairs for a NaN margin, which none meets
    if n.size == 0:
        return True
    f = int(np.argmin(lower[i, j, n]))
    one = slice(f, f + 1)
    if _exact_pairs(arm_a, q_a, arm_b, q_b, i[one], j[one], n[one])[0] < margin:
        return False
    return bool(np.all(_exact_pairs(arm_a, q_a, arm_b, q_b, i, j, n) >= margin))


def trajectory_min_distance(arm_a: ArmModel, t_a: ArrayLike, q_a: ArrayLike, arm_b: ArmModel,
                            t_b: ArrayLike, q_b: ArrayLike, start_b: float = 0.0,
                            max_step: float = MAX_TIME_STEP) -> Tuple[float, float]:
    """Smallest surface distance between two arms following time-stamped joint trajectories.

    Both trajectories are sampled on one time grid: every stamp of a, every stamp of b shifted
    by ``start_b``, and a uniform grid of spacing <= ``max_step`` over the whole span. Joint
    states are interpolated linearly between stamps; before its first stamp an arm holds its
    first state, after its last stamp its last state. The result is exact at the grid times;
    between them the distance can dip below it by at most the arms' relative speed times
    ``max_step / 2``. Only the capsule pairs that the box prefilter (see the module docstring)
    cannot rule out are computed exactly; the result is the full computation's.

    :param arm_a: the first arm (the leader).
    :param t_a: (N,) strictly increasing stamps of a, s.
    :param q_a: (N, 3) joint states of a.
    :param arm_b: the second arm.
    :param t_b: (M,) strictly increasing stamps of b, s (before the shift).
    :param q_b: (M, 3) joint states of b.
    :param start_b: shift of b's stamps, s (b's stamp ``t`` happens at ``t + start_b``).
    :param max_step: largest grid spacing, s.
    :return: ``(min_dist, t_at_min)``: the smallest distance (m, negative = penetration) and
        the first time it occurs, on a's clock (s).
    :raises ValueError: for malformed trajectories or a non-positive ``max_step``.
    """
    t_a, q_a = _check_trajectory(t_a, q_a, 'a')
    t_b, q_b = _check_trajectory(t_b, q_b, 'b')
    times, s_a, s_b = _grid_states(t_a, q_a, t_b, q_b, start_b, max_step)
    dist, k = _grid_min_distance(arm_a, s_a, arm_b, s_b)
    return dist, float(times[k])


def _sweep(arm: ArmModel, q: np.ndarray, resolution: float) -> np.ndarray:
    """Return states along the joint path ``q`` (N, 3) no point of the arm moves more between.

    A point of the arm moves at most ``(l1 + l2) |d theta1| + l2 |d theta2| + |d d3|`` between
    two states (joint-linear between them); the states returned are spaced by at most
    ``resolution`` of that, the given ones' first and last included.
    """
    q = np.asarray(q, dtype=float).reshape(-1, 3)
    if len(q) < 2:
        return q
    step = np.abs(np.diff(q, axis=0)) @ np.array([arm.l1 + arm.l2, arm.l2, 1.0])
    along = np.concatenate([[0.0], np.cumsum(step)])
    at = np.linspace(0.0, along[-1], max(2, int(np.ceil(along[-1] / resolution)) + 1))
    return np.column_stack([np.interp(at, along, q[:, k]) for k in range(3)])


def paths_apart(arm_a: ArmModel, q_a: ArrayLike, arm_b: ArmModel, q_b: ArrayLike,
                margin: float, resolution: float = 0.05) -> bool:
    """Return whether two arms keep ``margin`` wherever each is on its path, at any timing.

    Every state of a's joint path (``(N, 3)``, joint-linear between rows) against every state
    of b's: True only if no pair comes within ``margin``, so that however the two arms' clocks
    run against each other they stay apart. The paths are sampled at ``resolution`` of any
    point's travel (:func:`_sweep`), which the margin is grown by (half per arm).

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> left, right = cell.arms
    >>> home = np.array([[0.0, 0.0, 0.0]])
    >>> paths_apart(left, home, right, home, 0.1)
    True
    """
    a = _sweep(arm_a, q_a, resolution)
    b = _sweep(arm_b, q_b, resolution)
    i, j = np.divmod(np.arange(len(a) * len(b)), len(b))
    return _grid_safe(arm_a, a[i], arm_b, b[j], float(margin) + resolution)


def first_safe_delay(safe: Callable[[int], bool], max_delay: float, resolution: float = 0.01,
                     scan_step: float = 0.25) -> Optional[float]:
    """Smallest delay ``k * resolution`` that ``safe(k)`` accepts: a scan, then a bisection.

    Safety need not be monotonic in the delay, so the search scans ``k = 0, stride, ...``
    (``stride = scan_step / resolution``, rounded, at least 1) up to the last ``k`` within
    ``max_delay``; takes the first safe one; if it is not 0, bisects the interval from the
    unsafe scan point before it. The result was evaluated safe and its predecessor
    ``result - resolution`` unsafe; a safe island narrower than ``scan_step`` before the first
    safe scan point can be missed (the delay returned is then larger than needed, never one
    ``safe`` refused).

    :param safe: whether the delay ``k * resolution`` is safe, for an integer ``k >= 0``.
    :param max_delay: largest delay considered, s.
    :param resolution: the delay's resolution, s.
    :param scan_step: coarse scan spacing, s.
    :return: the delay in s (>= 0), or None if no scanned delay is safe.
    :raises ValueError: for non-positive ``resolution`` or negative ``max_delay``.

    Safe from 0.37 s on, the scan finds 0.5 and the bisection 0.37:

    >>> first_safe_delay(lambda k: k >= 37, max_delay=2.0)
    0.37
    """
    if not resolution > 0.0:
        raise ValueError(f'resolution must be > 0, got {resolution}')
    if not max_delay >= 0.0:
        raise ValueError(f'max_delay must be >= 0, got {max_delay}')
    last = int(np.floor(max_delay / resolution + 1e-9))
    stride = max(1, int(round(scan_step / resolution)))
    scan = list(range(0, last + 1, stride))
    if scan[-1] != last:
        scan.append(last)
    previous = None
    for k in scan:
        if safe(k):
            break
        previous = k
    else:
        return None
    if previous is None:
        return 0.0
    lo, hi = previous, k  # lo unsafe, hi safe
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if safe(mid):
            hi = mid
        else:
            lo = mid
    if not safe(hi):  # cannot happen (hi was evaluated safe); never return an unsafe delay
        return None
    return hi * resolution


def smallest_safe_delay(arm_a: ArmModel, t_a: ArrayLike, q_a: ArrayLike, arm_b: ArmModel,
                        t_b: ArrayLike, q_b: ArrayLike, margin: float, max_delay: float = 30.0,
                        resolution: float = 0.01, scan_step: float = 0.25,
                        max_step: float = MAX_TIME_STEP) -> Optional[float]:
    """Smallest start delay of trajectory b that keeps the arms ``margin`` apart.

    Arm a has priority and runs as planned; b holds its first state while it waits. The delays
    are searched by :func:`first_safe_delay` (a scan, then a bisection down to
    ``resolution``); the result was evaluated safe and ``result - resolution`` unsafe. A safe
    island narrower than ``scan_step`` before the first safe scan point can be missed (the
    delay returned is then larger than needed, never unsafe).

    A delay is safe when ``trajectory_min_distance(..., start_b=delay)[0] >= margin``; the check
    computes exactly only the capsule pairs whose box bound (module docstring) is below
    ``margin``, and stops at the first pair found too close. From the delay at which b starts
    after a has ended on, the check no longer depends on the delay (a moves while b waits at
    its first state, then b moves while a holds its last), so the search stops there: a b
    whose waiting pose is in a's way is refused after a few checks, not 120 (0.5 s of CPU).

    :param arm_a: the leader.
    :param t_a: (N,) stamps of a, s.
    :param q_a: (N, 3) joint states of a.
    :param arm_b: the arm that yields.
    :param t_b: (M,) stamps of b, s, before any delay.
    :param q_b: (M, 3) joint states of b.
    :param margin: required capsule surface distance, m (the cell's ``safety_margin``).
    :param max_delay: largest delay considered, s.
    :param resolution: the delay's resolution, s.
    :param scan_step: coarse scan spacing, s (rounded to a multiple of ``resolution``).
    :param max_step: largest time grid spacing of each check, as in
        :func:`trajectory_min_distance`, s.
    :return: the delay in s (>= 0), or None if no delay up to ``max_delay`` is safe: e.g. the
        final poses are too close (decided at once), or b's start pose, where it waits, is too
        close to where a works.
    :raises ValueError: for non-positive ``resolution`` or negative ``max_delay``.
    """
    t_a, q_a = _check_trajectory(t_a, q_a, 'a')
    t_b, q_b = _check_trajectory(t_b, q_b, 'b')
    # Whatever the delay, both arms end up holding their final states together.
    ends_apart = bool(arm_distance(arm_a, q_a[-1], arm_b, q_b[-1]) >= margin)

    def safe(k: int) -> bool:
        if not ends_apart:  # unsafe at every delay: decided without a check
            return False
        _, s_a, s_b = _grid_states(t_a, q_a, t_b, q_b, k * resolution, max_step)
        return _grid_safe(arm_a, s_a, arm_b, s_b, margin)

    if resolution > 0.0:  # (first_safe_delay refuses the others)
        settled = max(0.0, float(t_a[-1] - t_b[0]))  # b starts after a has ended from here
        max_delay = min(max_delay, np.ceil(settled / resolution - 1e-9) * resolution)
    return first_safe_delay(safe, max_delay, resolution, scan_step)
