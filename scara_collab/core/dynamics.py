"""Rigid-body dynamics of one SCARA arm: M(q), C(q, qd) qd, G(q), friction, ID and FD.

Stateless numpy functions; the :class:`~scara_collab.core.model.ArmModel` is passed explicitly
and is the only source of lengths, masses, centres of mass, inertias and friction. Every
function takes one state, shape ``(3,)``, or ``N`` states, shape ``(N, 3)`` (any leading shape
broadcasts), with the same code. Joint order ``q = (theta1, theta2, d3)`` in rad, rad, m.

Derivation (Lagrange, ``K = sum_b 1/2 m_b |v_b|^2 + 1/2 w_b . I_b w_b``)
--------------------------------------------------------------------------
Both revolute axes are +z and the quill slides along -z, so every body rotates about z only
and only the ``zz`` entry of each inertia tensor (about the body's com, in its link frame)
enters ``K``. Write ``(x_b, y_b)`` for the horizontal com of body ``b`` in its link frame:

* link 1 (com ``c1``): ``I1 = m1 (x1^2 + y1^2) + Izz1``.
* bodies riding on link 2 (link 2 itself, the quill, the payload point mass), with
  horizontal offsets from the elbow axis expressed in the link-2 frame:
  link 2 at ``(x2, y2)``, the quill at ``(l2 + xq, yq)``, the payload at ``(l2, 0)``.
  Their totals: ``m2t = m2 + mq + mp``, first moments ``sx = sum m_b x_b``,
  ``sy = sum m_b y_b`` and ``J2 = sum (m_b (x_b^2 + y_b^2) + Izz_b)`` (about the elbow axis).

The horizontal position of a body on link 2 is ``R(t1) (l1, 0) + R(t1 + t2) (x_b, y_b)``;
squaring its velocity and summing gives, with ``h(t2) = l1 (sx cos t2 - sy sin t2)``::

    M11 = I1 + m2t l1^2 + J2 + 2 h      M12 = M21 = J2 + h      M22 = J2
    M33 = mq + mp                       M13 = M23 = 0

``M13 = M23 = 0``: the quill moves along z, the revolute joints move everything in the
horizontal plane (their axes are vertical), and no horizontal position depends on ``d3``, so
the cross terms of ``|v|^2`` between ``d3_dot`` and ``theta_dot`` vanish. ``M`` depends on
``theta2`` only, so the Christoffel symbols leave (``beta = -h' = l1 (sx sin t2 + sy cos t2)``)::

    c1 = -beta (2 t1d t2d + t2d^2)      c2 = beta t1d^2      c3 = 0

Gravity ``(0, 0, -g)`` in the (upright) base frame: the potential is ``V = -(mq + mp) g d3``
(relative to ``d3 = 0``; positive ``d3`` lowers the quill), so ``G = dV/dq = (0, 0,
-(mq + mp) g)``: holding the quill still takes a *negative* (upward) joint force.

Example::

    >>> from scara_collab.core.model import load_cell
    >>> arm = load_cell().leader
    >>> tau = inverse_dynamics(arm, [0.3, -0.5, 0.1], [1.0, 0.5, 0.0], [0.0, 0.0, 0.0])
    >>> tau.shape
    (3,)
"""
from typing import NamedTuple, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core.model import ArmModel

Payload = Union[float, ArrayLike]
"""Payload mass at the tool tip, kg: a float, or an array broadcasting over the leading shape."""

STANDARD_GRAVITY = 9.81
"""Default gravitational acceleration, m/s^2 (SPEC section 1)."""


class _Inertial(NamedTuple):
    """The arm's inertial parameters collapsed to what ``M`` needs (see the module docstring)."""

    l1: float
    m11_const: Union[float, np.ndarray]   # I1 + m2t l1^2 + J2
    j2: Union[float, np.ndarray]
    sx: Union[float, np.ndarray]
    sy: Union[float, np.ndarray]
    m3: Union[float, np.ndarray]          # mq + mp


def _inertial(arm: ArmModel, payload: Payload) -> _Inertial:
    """Collapse the link inertias and the payload into the constants of ``M``."""
    if not np.isscalar(payload):
        payload = np.asarray(payload, dtype=float)
    l1, l2 = arm.l1, arm.l2
    b1, b2, bq = arm.link_1, arm.link_2, arm.quill
    i1 = b1.mass * (b1.com[0] ** 2 + b1.com[1] ** 2) + b1.inertia[2, 2]
    xq = l2 + bq.com[0]
    yq = bq.com[1]
    sx = b2.mass * b2.com[0] + bq.mass * xq + payload * l2
    sy = b2.mass * b2.com[1] + bq.mass * yq
    j2 = (b2.mass * (b2.com[0] ** 2 + b2.com[1] ** 2) + b2.inertia[2, 2]
          + bq.mass * (xq ** 2 + yq ** 2) + bq.inertia[2, 2] + payload * l2 ** 2)
    m2t = b2.mass + bq.mass + payload
    return _Inertial(l1, i1 + m2t * l1 ** 2 + j2, j2, sx, sy, bq.mass + payload)


def _state(x: ArrayLike, name: str) -> np.ndarray:
    """Return ``x`` as a float array whose last axis holds the three joints."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != 3:
        raise ValueError(f'{name} must have shape (3,) or (N, 3), got {x.shape}')
    return x


def _upright(arm: ArmModel) -> None:
    """Refuse a tilted base: gravity would then load the revolute joints as well."""
    if abs(arm.base[2, 2] - 1.0) > 1e-9:
        raise ValueError(f'{arm.name}: the dynamics assume an upright base (z axis vertical)')


def _mass_matrix(k: _Inertial, q: np.ndarray) -> np.ndarray:
    c2, s2 = np.cos(q[..., 1]), np.sin(q[..., 1])
    h = k.l1 * (k.sx * c2 - k.sy * s2)
    m = np.zeros(np.shape(h) + (3, 3))
    m[..., 0, 0] = k.m11_const + 2.0 * h
    m[..., 0, 1] = m[..., 1, 0] = k.j2 + h
    m[..., 1, 1] = k.j2
    m[..., 2, 2] = k.m3
    return m


def _coriolis(k: _Inertial, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    c2, s2 = np.cos(q[..., 1]), np.sin(q[..., 1])
    beta = k.l1 * (k.sx * s2 + k.sy * c2)
    w1, w2 = qd[..., 0], qd[..., 1]
    c_1 = -beta * (2.0 * w1 + w2) * w2       # carries the full broadcast shape
    out = np.zeros(np.shape(c_1) + (3,))
    out[..., 0] = c_1
    out[..., 1] = beta * w1 * w1
    return out


def _gravity(k: _Inertial, q: np.ndarray, g: float) -> np.ndarray:
    lead = q.shape[:-1]
    if np.ndim(k.m3):
        lead = np.broadcast_shapes(lead, np.shape(k.m3))
    out = np.zeros(lead + (3,))
    out[..., 2] = -k.m3 * g
    return out


def mass_matrix(arm: ArmModel, q: ArrayLike, payload: Payload = 0.0) -> np.ndarray:
    """Joint-space inertia matrix ``M(q)`` of the Lagrangian (see the module docstring).

    Includes every link's ``Izz`` about its com, the parallel-axis terms of link 1, link 2,
    the quill and the payload, and the quill + payload carried at the tool radius ``l2``.

    :param arm: the arm model (lengths and mass properties).
    :param q: (3,) or (N, 3) joint positions ``(theta1 rad, theta2 rad, d3 m)``.
    :param payload: point mass at the tool tip, kg.
    :return: (3, 3) or (N, 3, 3) symmetric positive definite ``M``; units kg m^2 (revolute
        block), kg (``M33``); the theta-d3 coupling entries are exactly zero.
    """
    return _mass_matrix(_inertial(arm, payload), _state(q, 'q'))


def coriolis(arm: ArmModel, q: ArrayLike, qd: ArrayLike, payload: Payload = 0.0) -> np.ndarray:
    """Coriolis and centrifugal generalised forces ``C(q, qd) qd`` from the Christoffel symbols.

    ``c_i = sum_jk 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_j qd_k`` of
    :func:`mass_matrix`; only ``dM/dtheta2`` is nonzero, which gives
    ``(-beta (2 qd1 + qd2) qd2, beta qd1^2, 0)`` with ``beta = l1 (sx sin t2 + sy cos t2)``.

    :param arm: the arm model.
    :param q: (3,) or (N, 3) joint positions (rad, rad, m).
    :param qd: (3,) or (N, 3) joint velocities (rad/s, rad/s, m/s).
    :param payload: point mass at the tool tip, kg.
    :return: (3,) or (N, 3) ``C(q, qd) qd`` in (N m, N m, N).
    """
    return _coriolis(_inertial(arm, payload), _state(q, 'q'), _state(qd, 'qd'))


def gravity(arm: ArmModel, q: ArrayLike, payload: Payload = 0.0,
            g: float = STANDARD_GRAVITY) -> np.ndarray:
    """Generalised gravity forces ``G(q) = dV/dq`` for gravity ``(0, 0, -g)``.

    The revolute axes are vertical, so their entries are zero; the quill axis is ``-z``, so
    ``G3 = -(m_quill + payload) g``: the joint force that holds the quill is negative (up).

    :param arm: the arm model; its base must be upright.
    :param q: (3,) or (N, 3) joint positions (rad, rad, m).
    :param payload: point mass at the tool tip, kg.
    :param g: gravitational acceleration, m/s^2 (positive; gravity points down).
    :return: (3,) or (N, 3) ``G`` in (N m, N m, N).
    :raises ValueError: if the arm's base is tilted.
    """
    _upright(arm)
    return _gravity(_inertial(arm, payload), _state(q, 'q'), g)


def friction(arm: ArmModel, qd: ArrayLike) -> np.ndarray:
    """Viscous + Coulomb joint friction ``F = viscous * qd + coulomb * sign(qd)``.

    Sign convention: ``F`` is the effort the friction *costs*, so it has the sign of ``qd``
    (the friction force on the joint, ``-F``, opposes motion) and it is *added* to the effort
    needed: ``tau = M qdd + C qd + G + F``. ``sign(0) = 0``: no stiction model.

    :param arm: the arm model (``viscous`` N m s/rad | N s/m, ``coulomb`` N m | N).
    :param qd: (3,) or (N, 3) joint velocities (rad/s, rad/s, m/s).
    :return: (3,) or (N, 3) ``F`` in (N m, N m, N).
    """
    qd = _state(qd, 'qd')
    return arm.viscous * qd + arm.coulomb * np.sign(qd)


def _bias(arm: ArmModel, q: ArrayLike, qd: ArrayLike, payload: Payload, g: float,
          with_friction: bool) -> Tuple[_Inertial, np.ndarray, np.ndarray]:
    """Return what both dynamics directions share: ``(k, q, C(q, qd) qd + G(q) [+ F(qd)])``.

    ``k`` are the arm's :func:`_inertial` constants with the payload, ``q`` the checked
    positions; the base must be upright.
    """
    _upright(arm)
    k = _inertial(arm, payload)
    q, qd = _state(q, 'q'), _state(qd, 'qd')
    bias = _coriolis(k, q, qd) + _gravity(k, q, g)
    if with_friction:
        bias = bias + friction(arm, qd)
    return k, q, bias


def inverse_dynamics(arm: ArmModel, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike,
                     payload: Payload = 0.0, g: float = STANDARD_GRAVITY,
                     with_friction: bool = True) -> np.ndarray:
    """Joint efforts for a motion: ``tau = M(q) qdd + C(q, qd) qd + G(q) [+ F(qd)]``.

    :param arm: the arm model; its base must be upright.
    :param q: (3,) or (N, 3) joint positions (rad, rad, m).
    :param qd: (3,) or (N, 3) joint velocities (rad/s, rad/s, m/s).
    :param qdd: (3,) or (N, 3) joint accelerations (rad/s^2, rad/s^2, m/s^2).
    :param payload: point mass at the tool tip, kg.
    :param g: gravitational acceleration, m/s^2.
    :param with_friction: add :func:`friction`.
    :return: (3,) or (N, 3) ``tau`` in (N m, N m, N).
    """
    k, q, bias = _bias(arm, q, qd, payload, g, with_friction)
    return (_mass_matrix(k, q) @ _state(qdd, 'qdd')[..., None])[..., 0] + bias


def forward_dynamics(arm: ArmModel, q: ArrayLike, qd: ArrayLike, tau: ArrayLike,
                     payload: Payload = 0.0, g: float = STANDARD_GRAVITY,
                     with_friction: bool = True) -> np.ndarray:
    """Joint accelerations under given efforts: ``qdd = M^-1 (tau - C qd - G [- F])``.

    The inverse of :func:`inverse_dynamics`, with the same parameters but ``tau`` (3,) or
    (N, 3) joint efforts (N m, N m, N) in place of ``qdd``; ``with_friction`` subtracts
    :func:`friction` (``sign(0) = 0``, so a joint at rest feels no Coulomb friction).

    :return: (3,) or (N, 3) ``qdd`` in (rad/s^2, rad/s^2, m/s^2).
    """
    k, q, bias = _bias(arm, q, qd, payload, g, with_friction)
    rhs = _state(tau, 'tau') - bias
    m = _mass_matrix(k, q)
    lead = np.broadcast_shapes(m.shape[:-2], rhs.shape[:-1])
    m, rhs = np.broadcast_to(m, lead + (3, 3)), np.broadcast_to(rhs, lead + (3,))
    return np.linalg.solve(m, rhs[..., None])[..., 0]


def kinetic_energy(arm: ArmModel, q: ArrayLike, qd: ArrayLike,
                   payload: Payload = 0.0) -> np.ndarray:
    """Kinetic energy ``K = 1/2 qd^T M(q) qd``.

    :param arm: the arm model.
    :param q: (3,) or (N, 3) joint positions (rad, rad, m).
    :param qd: (3,) or (N, 3) joint velocities (rad/s, rad/s, m/s).
    :param payload: point mass at the tool tip, kg.
    :return: () or (N,) kinetic energy, J.
    """
    qd = _state(qd, 'qd')
    m = mass_matrix(arm, q, payload)
    return 0.5 * np.einsum('...i,...ij,...j->...', qd, m, qd)


def potential_energy(arm: ArmModel, q: ArrayLike, payload: Payload = 0.0,
                     g: float = STANDARD_GRAVITY) -> np.ndarray:
    """Gravitational potential energy relative to ``d3 = 0``: ``V = -(m_quill + payload) g d3``.

    Consistent with :func:`gravity`: ``G = dV/dq``.

    :param arm: the arm model; its base must be upright.
    :param q: (3,) or (N, 3) joint positions (rad, rad, m).
    :param payload: point mass at the tool tip, kg.
    :param g: gravitational acceleration, m/s^2.
    :return: () or (N,) potential energy, J.
    """
    _upright(arm)
    q = _state(q, 'q')
    return -_inertial(arm, payload).m3 * g * q[..., 2]
