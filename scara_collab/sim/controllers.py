"""Joint servo laws of the simulator: PID on torque, and computed torque.

Both act on all arms at once: states are ``(A, 3)`` arrays (``A`` arms, joints ``theta1,
theta2, d3``), so one servo tick of the whole cell is one numpy evaluation. No PyBullet here.

* PID: ``tau = Kp e + Ki int(e) + Kd (qd_ref - qd)`` with ``e = q_ref - q``, the integral
  clamped so that ``|Ki int(e)|`` never exceeds the joint's effort limit (anti-windup). No
  gravity or inertia model: this is the design documents' controller, gains from
  ``controllers.yaml``.
* Computed torque: ``tau = M(q) (qdd_ref + Kp e + Kd (qd_ref - qd)) + C(q, qd) qd + G(q)
  + F(qd)``, evaluated as ``inverse_dynamics(q, qd, qdd_ref + Kp e + Kd e_dot)`` of
  :mod:`scara_collab.core.dynamics` with the held payload, plus the friction model the plant
  applies (:func:`smooth_friction`), so with an exact model the error obeys
  ``e'' + Kd e' + Kp e = 0``.

Example: both arms at rest on their references, the follower holding 0.5 kg; the torque is
what holds the quills up (``G``, negative: upward)::

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> ct = ComputedTorqueController(cell.arms, kp=[400] * 3, kd=[40] * 3)
    >>> q = qd = q_ref = qd_ref = qdd_ref = np.zeros((2, 3))
    >>> tau = ct(q, qd, q_ref, qd_ref, qdd_ref, payload=np.array([0.0, 0.5]))   # (2, 3)
    >>> tau.round(2)
    array([[  0. ,   0. , -23.3],
           [  0. ,   0. , -28.2]])
"""
import math
from typing import Dict, List, Sequence

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core.dynamics import inverse_dynamics, STANDARD_GRAVITY
from scara_collab.core.model import ArmModel


def smooth_friction(viscous: ArrayLike, coulomb: ArrayLike, qd: ArrayLike,
                    smoothing: float) -> np.ndarray:
    """Viscous + smoothed Coulomb friction effort ``viscous qd + coulomb tanh(qd / smoothing)``.

    The core model's ``sign(qd)`` made continuous, so that a joint at rest does not chatter
    between ``+coulomb`` and ``-coulomb`` from one physics step to the next. Same sign
    convention as :func:`scara_collab.core.dynamics.friction`: the effort friction *costs*
    (the plant applies ``-F``).

    :param viscous, coulomb: ``(3,)`` coefficients (N m s/rad | N s/m, N m | N).
    :param qd: ``(..., 3)`` joint velocities.
    :param smoothing: velocity scale of the tanh, rad/s | m/s (``> 0``).
    :return: ``(..., 3)`` friction effort.
    """
    qd = np.asarray(qd, dtype=float)
    return viscous * qd + coulomb * np.tanh(qd / smoothing)


def applied_efforts(tau: Sequence[float], viscous: Sequence[float], coulomb: Sequence[float],
                    qd: Sequence[float], smoothing: float) -> List[float]:
    """Return ``tau - smooth_friction(viscous, coulomb, qd, smoothing)`` on flat float lists.

    The physics loop's form of :func:`smooth_friction` (one call per 1 kHz step, six joints):
    plain floats and :func:`math.tanh`, a fifth of numpy's per-call cost on six values.

    >>> applied_efforts([1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [0.5, 0.0], 0.01)
    [-3.0, 0.0]
    """
    tanh = math.tanh
    return [t - (v * w + c * tanh(w / smoothing))
            for t, v, c, w in zip(tau, viscous, coulomb, qd)]


def joint_gains(group: Dict[str, Dict[str, float]], key: str) -> np.ndarray:
    """Per-joint gain vector ``(3,)`` from a ``{planar: {...}, quill: {...}}`` config group.

    :param group: e.g. ``load_config('controllers')['pid']``.
    :param key: ``kp``, ``ki`` or ``kd``.
    :return: ``(planar, planar, quill)``.
    """
    return np.array([group['planar'][key], group['planar'][key], group['quill'][key]], float)


class PidController:
    """Independent joint PID on torque for ``A`` arms (see the module docstring).

    :param kp, ki, kd: ``(3,)`` or ``(A, 3)`` gains (N m/rad, N m/(rad s), N m s/rad; N/m ...).
    :param max_effort: ``(3,)`` or ``(A, 3)`` effort limits, for the anti-windup clamp.
    :param arms: number of arms ``A``.
    """

    def __init__(self, kp: ArrayLike, ki: ArrayLike, kd: ArrayLike, max_effort: ArrayLike,
                 arms: int = 2):
        """Broadcast the gains to ``(A, 3)`` and zero the integrals."""
        shape = (arms, 3)
        self.kp = np.broadcast_to(np.asarray(kp, float), shape).copy()
        self.ki = np.broadcast_to(np.asarray(ki, float), shape).copy()
        self.kd = np.broadcast_to(np.asarray(kd, float), shape).copy()
        effort = np.broadcast_to(np.asarray(max_effort, float), shape)
        with np.errstate(divide='ignore'):
            self._limit = np.where(self.ki > 0, effort / np.where(self.ki > 0, self.ki, 1.0),
                                   0.0)
        self.integral = np.zeros(shape)

    def reset(self, arm: int = None) -> None:
        """Zero the integral of one arm (index) or of all arms."""
        if arm is None:
            self.integral[:] = 0.0
        else:
            self.integral[arm] = 0.0

    def __call__(self, q: np.ndarray, qd: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray,
                 dt: float) -> np.ndarray:
        """Torques ``(A, 3)`` for states and references ``(A, 3)``; advances the integral by dt.

        :param dt: servo period, s.
        """
        e = q_ref - q
        self.integral = np.clip(self.integral + e * dt, -self._limit, self._limit)
        return self.kp * e + self.ki * self.integral + self.kd * (qd_ref - qd)


def _inertial_key(arm: ArmModel) -> tuple:
    """Everything of an arm that :mod:`~scara_collab.core.dynamics` reads, except the base."""
    parts = [arm.l1, arm.l2, arm.viscous, arm.coulomb]
    for link in (arm.link_1, arm.link_2, arm.quill):
        parts += [link.mass, link.com, link.inertia]
    return tuple(np.round(np.concatenate([np.ravel(p) for p in parts]), 12).tolist())


class ComputedTorqueController:
    """Computed torque (inverse-dynamics feed-forward + PD outer loop) for ``A`` arms.

    When all arms share the same inertial parameters (the usual cell: one profile, bases
    differ only by pose) the whole cell is one vectorised
    :func:`~scara_collab.core.dynamics.inverse_dynamics` call with a per-arm payload.

    :param arms: the arm models (their bases must be upright).
    :param kp, kd: ``(3,)`` outer-loop gains (1/s^2, 1/s).
    :param g: gravitational acceleration, m/s^2.
    :param friction_smoothing: tanh scale of the Coulomb friction, as in the plant.
    """

    def __init__(self, arms: Sequence[ArmModel], kp: ArrayLike, kd: ArrayLike,
                 g: float = STANDARD_GRAVITY, friction_smoothing: float = 0.01):
        """Store the gains and the friction model; check whether the arms share inertias."""
        self.arms = tuple(arms)
        self.kp = np.asarray(kp, float)
        self.kd = np.asarray(kd, float)
        self.g = float(g)
        self._eps = float(friction_smoothing)
        self._viscous = np.stack([a.viscous for a in self.arms])
        self._coulomb = np.stack([a.coulomb for a in self.arms])
        self.shared = len({_inertial_key(a) for a in self.arms}) == 1

    def __call__(self, q: np.ndarray, qd: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray,
                 qdd_ref: np.ndarray, payload: np.ndarray) -> np.ndarray:
        """Torques ``(A, 3)`` for states and references ``(A, 3)`` and payloads ``(A,)`` kg."""
        qdd = qdd_ref + self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
        if self.shared:
            # a scalar payload when all arms carry the same (the usual 0 kg) is cheaper
            masses = payload.tolist()
            p = masses[0] if masses.count(masses[0]) == len(masses) else payload
            tau = inverse_dynamics(self.arms[0], q, qd, qdd, payload=p, g=self.g,
                                   with_friction=False)
        else:
            tau = np.stack([inverse_dynamics(a, q[i], qd[i], qdd[i], payload=payload[i],
                                             g=self.g, with_friction=False)
                            for i, a in enumerate(self.arms)])
        return tau + smooth_friction(self._viscous, self._coulomb, qd, self._eps)
