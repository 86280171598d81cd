"""SCARA kinematics: FK, analytical IK with both elbows, Jacobian, manipulability, DLS.

Joint vector ``q = (theta1, theta2, d3)``: theta1 = 0 points link 1 along the base's +x,
theta2 is relative to link 1, both counter-clockwise seen from above; d3 >= 0 lowers the tool.
In the base frame the tool tip is::

    x = L1 cos(theta1) + L2 cos(theta1 + theta2)
    y = L1 sin(theta1) + L2 sin(theta1 + theta2)
    z = tool_z0 - d3              (tool_z0 = shoulder height + elbow rise, 0.5 m)

Every function takes one state / target (shape ``(3,)``) or N of them (shape ``(N, 3)``).
The IK formula is written once over a small "ops" namespace and evaluated either with the
``math`` module (one target: a few microseconds) or with numpy (N targets: vectorised), so
the scalar case is the same code, not a copy.

Example::

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell(); left = cell.leader
    >>> sol = ik(left, [3.5, -1.0, 0.3])                  # world frame, no current state
    >>> np.degrees(sol.q[:2]).round(6), float(sol.q[2])   # the design documents' worked example
    (array([ 0., 90.]), 0.4)
"""
import math
from typing import NamedTuple, Optional, Union

import numpy as np

from scara_collab.core.model import ArmModel

ArrayLike = Union[np.ndarray, list, tuple]

# IK result codes, each with the rule that refused the target.
OK, NON_FINITE, TOO_FAR, TOO_CLOSE, QUILL_RANGE, JOINT_LIMIT = range(6)
REASONS = {
    OK: 'ok',
    NON_FINITE: 'non-finite target',
    TOO_FAR: 'unreachable: beyond the outer reach',
    TOO_CLOSE: 'unreachable: inside the inner reach',
    QUILL_RANGE: 'unreachable: height outside the quill travel',
    JOINT_LIMIT: 'joint limit: no elbow solution within the joint limits',
}


class IKError(ValueError):
    """A target was refused. ``code`` is one of the module's codes, ``reason`` says why."""

    def __init__(self, code: int, detail: str = ''):
        """Make the error for result ``code``; ``detail`` is appended to its reason."""
        self.code = int(code)
        self.reason = REASONS[self.code]
        super().__init__(self.reason + (f' ({detail})' if detail else ''))


class IKResult(NamedTuple):
    """Solutions for one target or N targets.

    :ivar q: ``(3,)`` or ``(N, 3)`` joint vectors; rows that were refused hold NaN.
    :ivar code: ``int`` or ``(N,)`` result codes (``OK`` = 0 for a solution).
    :ivar elbow: ``+1`` (elbow up, theta2 >= 0), ``-1`` (elbow down), 0 where refused.
    """

    q: np.ndarray
    code: Union[int, np.ndarray]
    elbow: Union[int, np.ndarray]

    @property
    def ok(self):
        """``True`` (or a boolean array) where a solution was found."""
        return self.code == OK

    def reasons(self):
        """Human-readable reason per target (``'ok'`` where solved)."""
        if np.ndim(self.code) == 0:
            return REASONS[int(self.code)]
        return [REASONS[int(c)] for c in self.code]

    def unwrap(self) -> np.ndarray:
        """Return ``q`` of a single target, or raise :class:`IKError` with the reason."""
        if np.ndim(self.code):
            bad = np.flatnonzero(self.code != OK)
            if bad.size:
                raise IKError(int(self.code[bad[0]]), f'target {bad[0]} of {self.code.size}')
            return self.q
        if self.code != OK:
            raise IKError(int(self.code))
        return self.q


class _ScalarOps:
    """``math`` versions of the few operations the IK formula uses."""

    sqrt = staticmethod(math.sqrt)
    arctan2 = staticmethod(math.atan2)
    arccos = staticmethod(math.acos)
    abs = staticmethod(abs)
    isfinite = staticmethod(math.isfinite)

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def clip(x, lo, hi):
        return lo if x < lo else hi if x > hi else x


class _VectorOps:
    """numpy versions of the same operations."""

    sqrt = staticmethod(np.sqrt)
    arctan2 = staticmethod(np.arctan2)
    arccos = staticmethod(np.arccos)
    abs = staticmethod(np.abs)
    isfinite = staticmethod(np.isfinite)
    where = staticmethod(np.where)
    clip = staticmethod(np.clip)


_TWO_PI = 2.0 * math.pi
_PI = math.pi
#: the base pose part of :attr:`ArmModel.constants` for base-frame targets (identity)
_IDENTITY_BASE = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def _wrap(a):
    """Wrap angles to [-pi, pi) (floats or arrays)."""
    return (a + _PI) % _TWO_PI - _PI


def _constants(arm: ArmModel, frame: str) -> tuple:
    """Return :attr:`ArmModel.constants` for targets in ``frame`` (``'world'`` or ``'base'``).

    For ``'base'`` the base pose is the identity: the same formula, base-frame numbers.
    """
    if frame not in ('world', 'base'):
        raise ValueError(f"frame must be 'world' or 'base', got {frame!r}")
    k = arm.constants
    return k if frame == 'world' else k[:5] + _IDENTITY_BASE + k[17:]


def _elbows(ops, k, x, y, z):
    """Both elbow solutions of targets ``(x, y, z)``, the IK formula written once.

    For ``ops`` = :class:`_ScalarOps` (floats) or :class:`_VectorOps` (arrays of any shape):
    the target goes into the base frame (``p_b = R^T (p - b)`` with ``k`` =
    :attr:`ArmModel.constants`), its plan-view radius is clamped into ``[|L1 - L2|, L1 + L2]``
    (a stretched or folded arm pointing at it) and::

        cos(theta2) = (r^2 - L1^2 - L2^2) / (2 L1 L2),   theta2_up = arccos(...) >= 0
        theta1 = atan2(y_b, x_b) -+ atan2(L2 sin(theta2_up), L1 + L2 cos(theta2_up))

    :return: ``(theta1_up, theta1_down, theta2_up, d3, r^2, (x_b, y_b, z_b))``; elbow down
        has ``theta2 = -theta2_up``.
    """
    l1, l2, z0 = k[0], k[1], k[2]
    r00, r01, r02, r10, r11, r12, r20, r21, r22, bx, by, bz = k[5:17]
    dx, dy, dz = x - bx, y - by, z - bz  # world -> base: p_b = R^T (p_w - b)
    xb = r00 * dx + r10 * dy + r20 * dz
    yb = r01 * dx + r11 * dy + r21 * dz
    zb = r02 * dx + r12 * dy + r22 * dz
    r2 = xb * xb + yb * yb
    cos2 = ops.clip((r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0, 1.0)
    t2 = ops.arccos(cos2)  # elbow up: theta2 >= 0
    alpha = ops.arctan2(yb, xb)
    beta = ops.arctan2(l2 * ops.sqrt(1.0 - cos2 * cos2), l1 + l2 * cos2)
    return _wrap(alpha - beta), _wrap(alpha + beta), t2, z0 - zb, r2, (xb, yb, zb)


def _ik_core(ops, k, x, y, z, c1, c2, has_current):
    """Both elbow solutions (:func:`_elbows`), the checks and the choice.

    Written once for ``ops`` = :class:`_ScalarOps` (floats) or :class:`_VectorOps` (arrays):
    only arithmetic, comparisons, ``&``/``|`` and the ops' functions, which both backends
    support. ``k`` is :attr:`ArmModel.constants`; ``c1, c2`` the current (theta1, theta2).
    Non-finite inputs propagate as NaN through the formula and are flagged by their code.
    """
    rmin, rmax = k[3], k[4]
    lo1, hi1, lo2, hi2, lo3, hi3 = k[17:23]
    t1_up, t1_dn, t2, d3, r2, (xb, yb, zb) = _elbows(ops, k, x, y, z)
    in_up = (lo1 <= t1_up) & (t1_up <= hi1) & (lo2 <= t2) & (t2 <= hi2)
    in_dn = (lo1 <= t1_dn) & (t1_dn <= hi1) & (lo2 <= -t2) & (-t2 <= hi2)
    cost_up = (t1_up - c1) ** 2 + (t2 - c2) ** 2
    cost_dn = (t1_dn - c1) ** 2 + (t2 + c2) ** 2
    up = in_up & ((in_dn ^ True) | (cost_up <= cost_dn) | (not has_current))
    code = ops.where(ops.isfinite(xb + yb + zb),
                     ops.where(r2 > rmax * rmax, TOO_FAR,
                               ops.where(r2 < rmin * rmin, TOO_CLOSE,
                                         ops.where((lo3 <= d3) & (d3 <= hi3),
                                                   ops.where(in_up | in_dn, OK, JOINT_LIMIT),
                                                   QUILL_RANGE))),
                     NON_FINITE)
    return ops.where(up, t1_up, t1_dn), ops.where(up, t2, -t2), d3, code, ops.where(up, 1, -1)


def ik(arm: ArmModel, target: ArrayLike, q_current: Optional[ArrayLike] = None,
       frame: str = 'world') -> IKResult:
    """Analytical IK for one target ``(3,)`` or N targets ``(N, 3)``.

    Both elbow solutions are computed; among those inside the joint limits the one with the
    least displacement of (theta1, theta2) from ``q_current`` is chosen, elbow up (theta2 >= 0)
    when there is no current state. Targets outside the reach window (``arm.reach_min`` ..
    ``arm.reach_max`` from the shoulder axis), outside the quill travel, non-finite, or with no
    elbow solution inside the limits are refused with a code (see :data:`REASONS`).

    :param arm: the arm model.
    :param target: tool-tip position(s), m, in ``frame``.
    :param q_current: current joint state(s), ``(3,)`` or ``(N, 3)``; optional.
    :param frame: ``'world'`` or ``'base'`` (the arm's base frame).
    :return: :class:`IKResult`.
    """
    k = _constants(arm, frame)
    tgt = target if type(target) in (tuple, list) else np.asarray(target, dtype=float)
    if len(tgt) == 3 and (tgt.ndim == 1 if type(tgt) is np.ndarray
                          else not hasattr(tgt[0], '__len__')):
        x, y, z = float(tgt[0]), float(tgt[1]), float(tgt[2])
        c1, c2 = (0.0, 0.0) if q_current is None else (float(q_current[0]),
                                                       float(q_current[1]))
        t1, t2, d3, code, elbow = _ik_core(_ScalarOps, k, x, y, z, c1, c2,
                                           q_current is not None)
        if code != OK:
            return IKResult(np.full(3, np.nan), code, 0)
        return IKResult(np.array((t1, t2, d3)), OK, elbow)
    tgt = np.asarray(tgt, dtype=float)
    if tgt.ndim != 2 or tgt.shape[1] != 3:
        raise ValueError(f'target must have shape (3,) or (N, 3), got {tgt.shape}')
    if q_current is None:
        c1 = c2 = np.zeros(len(tgt))
    else:
        qc = np.broadcast_to(np.asarray(q_current, dtype=float), tgt.shape)
        c1, c2 = qc[:, 0], qc[:, 1]
    with np.errstate(invalid='ignore'):  # non-finite targets are flagged, not warned about
        t1, t2, d3, code, elbow = _ik_core(_VectorOps, k, tgt[:, 0], tgt[:, 1], tgt[:, 2],
                                           c1, c2, q_current is not None)
    code = np.asarray(code, dtype=np.int8)
    q = np.stack((t1, t2, d3), axis=-1)
    bad = code != OK
    q[bad] = np.nan
    return IKResult(q, code, np.where(bad, 0, elbow).astype(np.int8))


def ik_both(arm: ArmModel, target: ArrayLike, frame: str = 'world') -> np.ndarray:
    """Both elbow solutions without limit checks: ``(..., 2, 3)``, elbow up first.

    Targets out of reach are clamped to the nearest reachable radius (a stretched or folded
    arm pointing at them): check reachability with :func:`ik` first. The formula is
    :func:`ik`'s (:func:`_elbows`).
    """
    tgt = np.asarray(target, dtype=float)
    t1_up, t1_dn, t2, d3, _, _ = _elbows(_VectorOps, _constants(arm, frame), tgt[..., 0],
                                         tgt[..., 1], tgt[..., 2])
    up = np.stack((t1_up, t2, d3), axis=-1)
    down = np.stack((t1_dn, -t2, d3), axis=-1)
    return np.stack((up, down), axis=-2)


def world_to_base(arm: ArmModel, p: ArrayLike) -> np.ndarray:
    """World point(s) ``(..., 3)`` into the arm's base frame: ``R^T (p - b)``.

    The leader's base is at (2, -2, 0.2), not rotated::

        >>> from scara_collab.core.model import load_cell
        >>> world_to_base(load_cell().leader, [3.5, -1.0, 0.3])
        array([1.5, 1. , 0.1])
    """
    p = np.asarray(p, dtype=float)
    return (p - arm.base[:3, 3]) @ arm.base[:3, :3]


def base_to_world(arm: ArmModel, p: ArrayLike) -> np.ndarray:
    """Base-frame point(s) ``(..., 3)`` into world: ``R p + b``.

    The inverse of :func:`world_to_base`::

        >>> from scara_collab.core.model import load_cell
        >>> base_to_world(load_cell().leader, [1.5, 1.0, 0.1])
        array([ 3.5, -1. ,  0.3])
    """
    p = np.asarray(p, dtype=float)
    return p @ arm.base[:3, :3].T + arm.base[:3, 3]


def homogeneous(arm: ArmModel, inverse: bool = False) -> np.ndarray:
    """Return the 4x4 transform world <- base (or base <- world with ``inverse=True``)."""
    if not inverse:
        return arm.base.copy()
    rot, b = arm.base[:3, :3], arm.base[:3, 3]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ b
    return out


def fk(arm: ArmModel, q: ArrayLike, frame: str = 'world') -> np.ndarray:
    """Tool-tip position(s) for joint state(s) ``(..., 3)``; returns ``(..., 3)`` in ``frame``."""
    q = np.asarray(q, dtype=float)
    t1, t12 = q[..., 0], q[..., 0] + q[..., 1]
    pb = np.stack((arm.l1 * np.cos(t1) + arm.l2 * np.cos(t12),
                   arm.l1 * np.sin(t1) + arm.l2 * np.sin(t12),
                   arm.tool_z0 - q[..., 2]), axis=-1)
    return base_to_world(arm, pb) if frame == 'world' else pb


def arm_points(arm: ArmModel, q: ArrayLike) -> np.ndarray:
    """World positions of shoulder, elbow and tool tip: ``(..., 3, 3)``, rows in that order.

    The shoulder and elbow are on the link-1 plane (z of the shoulder joint); the tool tip is
    at the end of the quill (``z = tool_z0 - d3`` in the base frame).
    """
    q = np.asarray(q, dtype=float)
    t1 = q[..., 0]
    zeros = np.zeros_like(t1)
    shoulder = np.stack((zeros, zeros, zeros + arm.shoulder_height), axis=-1)
    elbow = np.stack((arm.l1 * np.cos(t1), arm.l1 * np.sin(t1),
                      zeros + arm.shoulder_height), axis=-1)
    tool = fk(arm, q, frame='base')
    return base_to_world(arm, np.stack((shoulder, elbow, tool), axis=-2))


def jacobian(arm: ArmModel, q: ArrayLike, frame: str = 'world') -> np.ndarray:
    """Linear-velocity Jacobian of the tool tip, ``(..., 3, 3)``: ``p_dot = J q_dot``.

    In the base frame::

        [[-L1 s1 - L2 s12, -L2 s12,  0],
         [ L1 c1 + L2 c12,  L2 c12,  0],
         [ 0,               0,      -1]]
    """
    q = np.asarray(q, dtype=float)
    t1, t12 = q[..., 0], q[..., 0] + q[..., 1]
    s1, c1, s12, c12 = np.sin(t1), np.cos(t1), np.sin(t12), np.cos(t12)
    jac = np.zeros(q.shape[:-1] + (3, 3))
    jac[..., 0, 0] = -arm.l1 * s1 - arm.l2 * s12
    jac[..., 0, 1] = -arm.l2 * s12
    jac[..., 1, 0] = arm.l1 * c1 + arm.l2 * c12
    jac[..., 1, 1] = arm.l2 * c12
    jac[..., 2, 2] = -1.0
    return arm.base[:3, :3] @ jac if frame == 'world' else jac


def det_jacobian(arm: ArmModel, q: ArrayLike) -> np.ndarray:
    """Return det of the planar 2x2 block, ``L1 L2 sin(theta2)`` (zero at theta2 = 0, pi)."""
    return arm.l1 * arm.l2 * np.sin(np.asarray(q, dtype=float)[..., 1])


def manipulability(arm: ArmModel, q: ArrayLike) -> np.ndarray:
    """Yoshikawa's measure of the planar block, ``sqrt(det(J J^T)) = |L1 L2 sin(theta2)|``."""
    return np.abs(det_jacobian(arm, q))


def dls_damping(w: ArrayLike, threshold: float, max_damping: float) -> np.ndarray:
    """Damping factor lambda for manipulability ``w``: zero above ``threshold``, rising smoothly.

    ``lambda^2 = max_damping^2 (1 - w / threshold)^2`` for ``w < threshold`` (Nakamura and
    Hanafusa's variable damping), so the DLS inverse equals the exact inverse away from
    singularities and lambda reaches ``max_damping`` at ``w = 0``; lambda and its slope in
    ``w`` are continuous at the threshold.

    >>> dls_damping([0.0, 0.25, 0.5, 1.0], threshold=0.5, max_damping=0.15)
    array([0.15 , 0.075, 0.   , 0.   ])
    """
    w = np.asarray(w, dtype=float)
    ratio = np.clip(1.0 - w / threshold, 0.0, 1.0)
    return max_damping * ratio


def dls_solve(arm: ArmModel, q: ArrayLike, v: ArrayLike, threshold: float = 0.5,
              max_damping: float = 0.15, frame: str = 'world') -> np.ndarray:
    """Joint velocity for a tool velocity: the minimum-norm (Lagrange multiplier) solution.

    Solves ``min |q_dot|^2 s.t. J q_dot = v``, i.e. ``q_dot = J^T (J J^T)^-1 v``, damped near
    singularity: ``q_dot = J^T (J J^T + lambda^2 I)^-1 v`` with :func:`dls_damping`.

    :param q: joint state(s) ``(..., 3)``.
    :param v: tool velocity ``(..., 3)``, m/s, in ``frame``.
    :return: joint velocities ``(..., 3)``.
    """
    jac = jacobian(arm, q, frame=frame)
    lam = dls_damping(manipulability(arm, q), threshold, max_damping)
    jjt = jac @ np.swapaxes(jac, -1, -2)
    jjt = jjt + (lam ** 2)[..., None, None] * np.eye(3)
    v = np.asarray(v, dtype=float)
    y = np.linalg.solve(jjt, v[..., None])[..., 0]
    return (np.swapaxes(jac, -1, -2) @ y[..., None])[..., 0]


def within_limits(arm: ArmModel, q: ArrayLike, tol: float = 1e-9) -> np.ndarray:
    """Return ``True`` where every joint of ``q`` ``(..., 3)`` is inside its position limits."""
    q = np.asarray(q, dtype=float)
    return np.all((q >= arm.lower - tol) & (q <= arm.upper + tol), axis=-1)
