"""Speed and separation monitoring (ISO/TS 15066): the protective separation, the allowed speed.

The protective separation distance of ISO/TS 15066:2016 section 5.5.4 (as reproduced by Marvel
and Norcross, *Implementing speed and separation monitoring in collaborative robot workcells*,
RCIM 44 (2017), and by Veo Robotics)::

    S_p = S_h + S_r + S_s + C + Z_d + Z_r

    S_h = v_h (T_r + T_s)   the person's travel while the arm reacts and stops
    S_r = v_r T_r           the arm's travel towards the person during the reaction time
    S_s                     the arm's stopping distance towards the person (v_r T_s / 2 when
                            it brakes uniformly)
    C                       the intrusion distance (ISO 13855): how far a body part reaches past
                            the point where the sensor sees the person
    Z_d, Z_r                the position uncertainty of the sensor and of the arm

``v_h`` is the person's speed towards the arm, ``v_r`` the arm's *directed* speed (towards the
person), ``T_r`` the reaction time of the whole chain (sensor, monitor, controller) and ``T_s``
the arm's stopping time.

**The allowed speed.** An arm runs its trajectory at a fraction ``s`` of its planned speed
(:class:`scara_collab.core.scaled_clock.ScaledClock`). At ``s`` its directed speed is
``s v_r``, and a stop that keeps the path (every joint slowed in proportion) takes ``s T_s``
and covers ``s^2 S_s``: each joint's speed, stopping time and stopping distance scale so. With
``C' = C + Z_d + Z_r``::

    S_p(s) = (v_h T_r + C') + s (v_h T_s + v_r T_r) + s^2 S_s

and the largest ``s`` in [0, 1] with ``S_p(s) <= S`` is the positive root of that quadratic
(:func:`allowed_scale`). For uniform braking at ``a`` (``T_s = v_r / a``,
``S_s = v_r^2 / (2 a)``) the allowed speed ``s v_r`` is the closed form of the research notes
(section 1.1, CNR's ``ssm_safe_velocity_limits``), :func:`max_robot_speed`::

    v_r,max(D) = -a T_r - v_h + sqrt(a^2 T_r^2 + v_h^2 + 2 a (D - C'))

Along the links' arcs the stop's reach scales only nearly as ``s^2``, so :func:`assess_arm`
weighs the arm again at the velocity the root slows it to and lowers the factor while the
margin there is negative (:data:`REFINE_STEPS`).

If even ``S_p(0)`` exceeds ``S`` the arm must stand: a protective stop.

**What a floor scanner sees.** A 2-D safety laser scanner sees a person's legs in its scan plane
at height H. It cannot see the arms, the lean of the body or its height, so the monitor treats
a person as a vertical column around what it sees (:class:`Person`), tall enough to cover every
link, and ISO 13855 supplies the reach over the column, ``C = 1200 - 0.4 H`` mm, at least
850 mm (:func:`intrusion_distance`): at H = 0.3 m, C = 1.08 m, more than the 0.85 m forward
reach of an arm (ISO 13857).

**The arm's side.** :func:`assess_arm` takes every capsule of the arm
(:func:`scara_collab.core.collision.arm_capsules`) at a few points along it and at its exact
closest point to each person, each point with its velocity (the links are rigid, so a point's
velocity is the blend of its capsule's end velocities; the tool's comes from
:func:`scara_collab.core.kinematics.jacobian`). Per point: the separation ``S`` to the column
(capsule surface to column surface), the directed speed ``v_r`` (the point's velocity along the
line to the person, 0 if it moves away), the stopping time ``T_s`` of the arm
(:func:`scara_collab.core.safety.stopping_time`) and the stopping distance ``S_s`` towards the
person, the farthest the point gets along that line while the arm stops, both by braking every
joint at its limit (:func:`scara_collab.core.safety.braking`) and by the path-keeping stop (all
joints slowed together, all at rest after ``T_s``; the larger of the two counts). The arm's
factor is the smallest over the points and persons.

This is a simulation of a safety function, not a certified one.
"""
from dataclasses import dataclass, replace
import math
from typing import Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core import collision, safety
from scara_collab.core.kinematics import arm_points, jacobian
from scara_collab.core.model import ArmModel

#: ISO 13855, detection zone parallel to the approach (a horizontal field at height H):
#: C = 1200 mm - 0.4 H, but not less than 850 mm, for H up to 1000 mm.
INTRUSION_AT_FLOOR = 1.2
INTRUSION_SLOPE = 0.4
INTRUSION_MIN = 0.85
INTRUSION_MAX_HEIGHT = 1.0
#: The points sampled along link 1 and link 2 (fractions of the capsule axis); the quill's two
#: ends. Each capsule's exact closest point to each person is added.
LINK_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
LINK_NAMES = ('link 1', 'link 2', 'quill')
_CAPSULE = np.array([0] * 5 + [1] * 5 + [2] * 2)
_FRACTION = np.array(LINK_FRACTIONS * 2 + (0.0, 1.0))
#: The points :func:`assess_arm` checks: each capsule's closest point to the person, then the
#: fixed samples; their capsules, fractions (of the samples) and whether they are samples.
_POINT_CAPSULE = np.concatenate([np.arange(3), _CAPSULE])
_POINT_FRACTION = np.concatenate([np.zeros(3), _FRACTION])
_FIXED = np.arange(len(_POINT_CAPSULE)) >= 3
#: samples of each stop trajectory that gives the stopping distance (its time step is T_s / this)
STOP_SAMPLES = 8
#: The quadratic of the allowed factor holds exactly in joint space; along the links' arcs a
#: stop's reach towards the person scales only nearly as ``s^2``, so its root can overshoot
#: (in 3000 random poses, velocities and persons: 172 of the 270 factors between 0 and 1, by
#: up to 9.8 cm of margin). :func:`assess_arm` checks the factor at the velocity it slows to
#: and, while the margin there is negative, multiplies it by the square of what that velocity
#: allows (the plain step converges from above, slowly: -1.9e-5 m still after 4 steps; the
#: doubled one landed on the safe side in one step in all 3000, lowering the factor by 0.005
#: on average), at most this often.
REFINE_STEPS = 4


def intrusion_distance(height: float) -> float:
    """Return ISO 13855's intrusion distance C for a horizontal field at ``height``, m.

    ``C = 1.2 - 0.4 H`` (m), at least 0.85 m, for ``0 <= H <= 1.0`` m.

    >>> round(intrusion_distance(0.3), 6), intrusion_distance(1.0)
    (1.08, 0.85)

    :raises ValueError: for a height outside [0, 1] m.
    """
    if not 0.0 <= height <= INTRUSION_MAX_HEIGHT:
        raise ValueError(f'ISO 13855 covers horizontal fields 0 to {INTRUSION_MAX_HEIGHT} m '
                         f'high, got {height} m')
    return max(INTRUSION_MIN, INTRUSION_AT_FLOOR - INTRUSION_SLOPE * height)


def protective_separation(v_h: ArrayLike, v_r: ArrayLike, t_r: ArrayLike, t_s: ArrayLike,
                          s_s: ArrayLike, c: ArrayLike) -> np.ndarray:
    """Return ``S_p = v_h (T_r + T_s) + v_r T_r + S_s + C'`` (arrays broadcast).

    :param v_h: the person's speed towards the arm, m/s.
    :param v_r: the arm's directed speed towards the person, m/s.
    :param t_r: reaction time, s.
    :param t_s: the arm's stopping time, s.
    :param s_s: the arm's stopping distance towards the person, m.
    :param c: ``C + Z_d + Z_r``, m.
    :return: the protective separation distance, m.

    The notes' worked example (section 1.6): a 2-D scanner at 0.3 m, the arm at 3 m/s stopping
    in 1/3 s, T_r = 0.15 s, v_h = 1.6 m/s, Z_d + Z_r = 0.11 m::

        >>> round(float(protective_separation(1.6, 3.0, 0.15, 1 / 3, 0.5, 1.08 + 0.11)), 3)
        2.913
    """
    v_h, v_r, t_r, t_s, s_s, c = (np.asarray(x, dtype=float)
                                  for x in (v_h, v_r, t_r, t_s, s_s, c))
    return v_h * (t_r + t_s) + v_r * t_r + s_s + c


def max_robot_speed(d: ArrayLike, v_h: ArrayLike, a: ArrayLike, t_r: ArrayLike,
                    c: ArrayLike) -> np.ndarray:
    """Return the largest directed speed at separation ``d`` for uniform braking at ``a``.

    ``v_r,max = -a T_r - v_h + sqrt(a^2 T_r^2 + v_h^2 + 2 a (d - C'))``, 0 where negative
    (the research notes, section 1.1). Arrays broadcast.

    :param d: separation, m; :param v_h: the person's speed, m/s; :param a: the arm's
        braking deceleration, m/s^2 (> 0); :param t_r: reaction time, s; :param c: ``C'``, m.

    The notes' table (``C' = 0.3``, ``T_r = 0.15``, ``v_h = 1.6``, ``a = 3``)::

        >>> np.round(max_robot_speed([0.5, 1.0, 2.0], 1.6, 3.0, 0.15, 0.3), 2)
        array([0.  , 0.59, 1.55])
    """
    d, v_h, a, t_r, c = (np.asarray(x, dtype=float) for x in (d, v_h, a, t_r, c))
    root = np.sqrt(np.maximum(a * a * t_r * t_r + v_h * v_h + 2.0 * a * (d - c), 0.0))
    return np.maximum(-a * t_r - v_h + root, 0.0)


def allowed_scale(d: ArrayLike, v_h: ArrayLike, v_r: ArrayLike, t_r: ArrayLike,
                  t_s: ArrayLike, s_s: ArrayLike, c: ArrayLike) -> np.ndarray:
    """Return the largest ``s`` in [0, 1] with ``S_p(s) <= d`` (module docstring).

    ``S_p(s) = (v_h T_r + C') + s (v_h T_s + v_r T_r) + s^2 S_s``: the root
    ``s = 2 k / (b + sqrt(b^2 + 4 S_s k))`` with ``k = d - v_h T_r - C'`` and
    ``b = v_h T_s + v_r T_r`` (the form that stays accurate when ``S_s`` is small); 0 if
    ``k <= 0`` (stop), 1 if the arm may run at full speed. Arrays broadcast.

    :param d: separation, m; :param v_h: the person's speed, m/s; :param v_r: the arm's directed
        speed at ``s = 1``, m/s; :param t_r: reaction time, s; :param t_s: stopping time at
        ``s = 1``, s; :param s_s: stopping distance at ``s = 1``, m; :param c: ``C'``, m.

    With uniform braking it is :func:`max_robot_speed` over ``v_r``::

        >>> v_r, a = 3.0, 6.0
        >>> s = allowed_scale(1.5, 1.6, v_r, 0.15, v_r / a, v_r ** 2 / (2 * a), 0.3)
        >>> round(float(s * v_r), 6) == round(float(max_robot_speed(1.5, 1.6, a, 0.15, 0.3)), 6)
        True
    """
    d, v_h, v_r, t_r, t_s, s_s, c = (np.asarray(x, dtype=float)
                                     for x in (d, v_h, v_r, t_r, t_s, s_s, c))
    k = d - v_h * t_r - c
    b = v_h * t_s + v_r * t_r
    denom = b + np.sqrt(np.maximum(b * b + 4.0 * s_s * np.maximum(k, 0.0), 0.0))
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        s = np.where(denom > 0.0, 2.0 * k / np.where(denom > 0.0, denom, 1.0), np.inf)
    return np.where(k > 0.0, np.clip(s, 0.0, 1.0), 0.0)


def approach_speed(walking: float, reach: float, reach_limit: float,
                   separation_with_reach: ArrayLike) -> np.ndarray:
    """Return the person's approach speed ``v_h`` by ISO 13855's rule.

    The upper arm's 2.0 m/s counts where the distance computed with it is at most 0.5 m; beyond,
    the walking speed 1.6 m/s (a body cannot keep an arm's speed over a longer approach).

    >>> approach_speed(1.6, 2.0, 0.5, [0.4, 1.4])
    array([2. , 1.6])
    """
    return np.where(np.asarray(separation_with_reach, dtype=float) <= reach_limit, reach,
                    walking)


@dataclass(frozen=True)
class SsmParams:
    """The numbers of the protective separation (``config/people.yaml``, ``monitor``).

    :ivar walking_speed: ``v_h`` of a walking person, m/s (ISO 13855: 1.6).
    :ivar reach_speed: an upper arm's speed, m/s (ISO 13855: 2.0), counted where the distance
        computed with it is at most ``reach_limit`` (m).
    :ivar reaction_time: ``T_r``, s.
    :ivar intrusion: ``C``, m (:func:`intrusion_distance`).
    :ivar sensor_tolerance: ``Z_d``, m.
    :ivar robot_tolerance: ``Z_r``, m.
    :ivar hysteresis: m taken off the separation for the factor a rise may reach.
    :ivar stop_allowance: how many times its braking time ``T_s`` an arm's path-keeping stop
        is allowed (at least 1): the stop counted on (and what the bridge brakes to when a
        trajectory's own accelerations leave less room, :mod:`scara_collab.core.scaled_clock`).
    """

    walking_speed: float
    reach_speed: float
    reach_limit: float
    reaction_time: float
    intrusion: float
    sensor_tolerance: float
    robot_tolerance: float
    hysteresis: float = 0.0
    stop_allowance: float = 1.0

    @property
    def constant(self) -> float:
        """``C' = C + Z_d + Z_r``, m."""
        return self.intrusion + self.sensor_tolerance + self.robot_tolerance

    @staticmethod
    def from_config(cfg: dict) -> 'SsmParams':
        """Build them from the validated ``people`` config (C from the scan height)."""
        mon = cfg['monitor']
        return SsmParams(
            walking_speed=float(mon['walking_speed']), reach_speed=float(mon['reach_speed']),
            reach_limit=float(mon['reach_limit']),
            reaction_time=float(sum(mon['reaction'][k] for k in ('scanner', 'monitor',
                                                                 'bridge'))),
            intrusion=intrusion_distance(float(cfg['scanner']['height'])),
            sensor_tolerance=float(mon['sensor_tolerance']),
            robot_tolerance=float(mon['robot_tolerance']),
            hysteresis=float(mon['hysteresis']),
            stop_allowance=float(mon['stop_allowance']))


@dataclass(frozen=True)
class Person:
    """A person as the monitor sees one: a vertical column on the floor.

    :ivar position: ``(2,)`` centre on the floor, world, m.
    :ivar velocity: ``(2,)`` m/s (zeros if unknown).
    :ivar radius: m; :ivar height: m, the column's top above the floor.
    :ivar id: the track's number.
    """

    position: np.ndarray
    velocity: np.ndarray
    radius: float
    height: float
    id: int = 0


@dataclass(frozen=True)
class ArmSeparation:
    """One arm against the persons it could reach (:func:`assess_arm`).

    :ivar robot: the arm's name.
    :ivar separation: the smallest ``S``, m (``inf`` without a person).
    :ivar margin: the smallest ``S - S_p`` at the arm's planned speed (``s = 1``), m.
    :ivar scale: the allowed factor ``s`` in [0, 1].
    :ivar relaxed: the factor allowed with ``S`` less the hysteresis (what a rise may reach).
    :ivar stop: True if ``S < S_p`` with the arm at rest: a protective stop.
    :ivar cause: why the factor is below 1 (or why the arm stops), else ``''``.
    :ivar stopping_time: ``T_s`` at ``s = 1``, s.
    """

    robot: str
    separation: float
    margin: float
    scale: float
    relaxed: float
    stop: bool
    cause: str
    stopping_time: float


#: The capsules' ends as rows of :func:`node_velocities`: link 1 runs from the shoulder (0) to
#: the elbow (1), link 2 from the elbow to the quill axis (2), and the quill moves as the tool
#: tip (3) does. A point at fraction ``u`` of a rigid capsule moves at
#: ``(1 - u) v_start + u v_end``.
_ENDS = np.array([[0, 1], [1, 2], [3, 3]])
_FIRST, _LAST = _ENDS[_POINT_CAPSULE, 0], _ENDS[_POINT_CAPSULE, 1]


def _node_positions(arm: ArmModel, q: ArrayLike) -> np.ndarray:
    """Return the rows of :func:`node_velocities` as positions up to constant offsets.

    ``(..., 4, 3)``: the shoulder, the elbow, the tool at the shoulder's height and the tool
    tip (:func:`~scara_collab.core.kinematics.arm_points`). The difference between two states is
    how far each capsule end moved: the capsules' ends sit at constant offsets from these.
    """
    pts = arm_points(arm, q)
    up = arm.base[:3, 2]
    planar = pts[..., 2, :] - np.multiply.outer((pts[..., 2, :] - pts[..., 0, :]) @ up, up)
    return np.concatenate([pts[..., :2, :], planar[..., None, :], pts[..., 2:, :]], axis=-2)


def node_velocities(arm: ArmModel, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
    """Return the velocities of the shoulder, the elbow, the quill axis and the tool tip.

    The shoulder is at rest, the elbow turns with joint 1, the tool tip moves at ``J(q) qd``
    (:func:`~scara_collab.core.kinematics.jacobian`) and the quill axis at link 2's height
    moves as the tool does without the quill's own rate.

    :param q: ``(3,)`` joints; :param qd: ``(3,)`` joint velocities.
    :return: ``(4, 3)``, world, m/s.
    """
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    elbow = arm.base[:3, :3] @ np.array([-math.sin(q[0]), math.cos(q[0]), 0.0])
    jac = jacobian(arm, q)
    return np.stack([np.zeros(3), arm.l1 * qd[0] * elbow, jac[:, :2] @ qd[:2], jac @ qd])


def _stops(arm: ArmModel, q: np.ndarray, qd: np.ndarray, t_s: float) -> np.ndarray:
    """Return the arm's joint states while it stops, both ways: ``(M, 3)``.

    Braking every joint at its limit (:func:`~scara_collab.core.safety.braking`), and the
    path-keeping stop, every joint slowed uniformly to rest at ``t_s``:
    ``q + qd (t - t^2 / (2 t_s))``, in which each joint moves ``qd t_s / 2``, at least its
    braking distance ``qd^2 / (2 a)``.
    """
    t, braked, _, _ = safety.braking(arm, q, qd, max(t_s / STOP_SAMPLES, 1e-3))
    if t_s <= 0.0:
        return braked
    tt = t[:, None]
    return np.concatenate([braked, q + qd * (tt - tt * tt / (2.0 * t_s))])


def _columns(persons: Sequence[Person]):
    """Return the persons' column axes, velocities and radii as arrays (P rows)."""
    pos = np.array([p.position for p in persons], dtype=float).reshape(-1, 2)
    bottom = np.column_stack([pos, np.zeros(len(pos))])
    top = np.column_stack([pos, [p.height for p in persons]])
    vel = np.array([p.velocity for p in persons], dtype=float).reshape(-1, 2)
    return bottom, top, vel, np.array([p.radius for p in persons], dtype=float)


def assess_arm(arm: ArmModel, q: ArrayLike, qd: ArrayLike, persons: Sequence[Person],
               params: SsmParams, refine: Optional[int] = None) -> ArmSeparation:
    """Return the separation of one arm from the persons and the speed factor it allows.

    The module docstring says which points count, at which speeds, and how far they stop.

    :param arm: the arm.
    :param q: ``(3,)`` its joint positions.
    :param qd: ``(3,)`` the joint velocities it is weighed at, the speed factor's reference:
        its *planned* ones, unscaled (the trajectory's at the arm's trajectory time,
        :meth:`ScaledClock.planned_velocity
        <scara_collab.core.scaled_clock.ScaledClock.planned_velocity>`, or the fastest within
        a horizon), or its measured ones (the monitor weighs it at both,
        :meth:`scara_collab.core.separation_monitor.SeparationMonitor.decide`).
    :param persons: the persons, as columns.
    :param params: the protective separation's numbers.
    :param refine: how often at most the factor is checked where it slows the arm (default
        :data:`REFINE_STEPS`; 0: the quadratic's root, as :func:`allowed_along` weighs).
    :return: the :class:`ArmSeparation`.
    """
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    if not persons:
        return ArmSeparation(arm.name, math.inf, math.inf, 1.0, 1.0, False, '',
                             safety.stopping_time(arm, qd))
    bottom, top, v_person, r_person = _columns(persons)
    return _assess(arm, q, qd, bottom, top, v_person, r_person, params,
                   [f'person {p.id} at ({p.position[0]:.2f}, {p.position[1]:.2f})'
                    for p in persons], REFINE_STEPS if refine is None else refine)


def true_margin(arm: ArmModel, q: ArrayLike, qd: ArrayLike, starts: ArrayLike, ends: ArrayLike,
                radii: ArrayLike, params: SsmParams) -> Tuple[float, float]:
    """Return an arm's true separation from a body of capsules and its margin over ``S_p``, m.

    The ground truth a simulation knows and a scanner does not: the body's own capsules (an
    arm reaching out included), so neither the intrusion distance ``C`` nor the sensor's
    tolerance ``Z_d`` comes into ``S_p``; the person's speed towards the arm is the standard's
    (walking, or reaching within ``reach_limit``), the arm's its own (``qd``: its measured
    joint velocities). A non-negative margin means: had the person come straight at the arm
    at the standard's speed, the arm would have stopped before they met.

    :param q, qd: ``(3,)`` the arm's joints and joint velocities.
    :param starts, ends: ``(B, 3)`` the body's capsule axes, world, m; :param radii: ``(B,)``.
    :return: ``(separation, margin)``.
    """
    truth = replace(params, intrusion=0.0, sensor_tolerance=0.0)
    starts, ends = np.asarray(starts, dtype=float), np.asarray(ends, dtype=float)
    out = _assess(arm, np.asarray(q, dtype=float), np.asarray(qd, dtype=float), starts, ends,
                  np.zeros((len(starts), 2)), np.asarray(radii, dtype=float), truth,
                  ['the body'] * len(starts))
    return out.separation, out.margin


def true_separation_bound(arm: ArmModel, params: SsmParams) -> float:
    """Return an upper bound of the protective separation :func:`true_margin` counts, m.

    At the arm's fastest: its tool at ``(l1 + l2) w1 + l2 w2 + vz`` of its velocity limits
    (every other point is slower), stopping along its path in ``stop_allowance`` times its
    longest braking time and covering at most half of that at this speed, the person at the
    faster of the standard's speeds. Beyond it from an arm's reach nothing needs an exact
    look: the margin is at least the floor distance less this.

    >>> from scara_collab.core.model import load_cell
    >>> round(true_separation_bound(load_cell().leader, SsmParams(1.6, 2.0, 0.5, 0.12, 0.0,
    ...                                                           0.0, 0.01, 0.0, 2.0)), 2)
    4.98
    """
    w = np.abs(arm.max_velocity)
    v = (arm.l1 + arm.l2) * w[0] + arm.l2 * w[1] + w[2]
    t_s = params.stop_allowance * float(np.max(w / arm.max_acceleration))
    v_h = max(params.walking_speed, params.reach_speed)
    return float(v_h * (params.reaction_time + t_s) + v * params.reaction_time + v * t_s / 2.0
                 + params.robot_tolerance)


def _assess(arm: ArmModel, q: np.ndarray, qd: np.ndarray, bottom: np.ndarray, top: np.ndarray,
            v_person: np.ndarray, r_person: np.ndarray, params: SsmParams,
            labels: Sequence[str], refine: int = 0) -> ArmSeparation:
    """Assess ``arm`` against bodies given as capsule axes ``bottom`` .. ``top`` (P rows).

    :param v_person: ``(P, 2)`` each body's velocity on the floor, m/s; :param r_person:
        ``(P,)`` radii, m; :param labels: each body in words (for the cause).
    :param refine: how many times at most the factor is checked at the velocity it slows to,
        and lowered while the margin there is negative (:data:`REFINE_STEPS`; 0: the
        quadratic's root as it is).
    """
    t_s = params.stop_allowance * safety.stopping_time(arm, qd)
    # the arm's capsules now and while it stops, from the one capsule model: (1 + M, 3, 3)
    start, end, radii = collision.arm_capsules(arm, q)
    # one segment distance for the capsules (their closest points) and the fixed samples
    p0 = np.concatenate([start, start[_CAPSULE] + _FRACTION[:, None] * (end - start)[_CAPSULE]])
    p1 = np.concatenate([end, p0[3:]])
    axis_dist, u, t_col = collision.segment_distance(p0[None], p1[None], bottom[:, None],
                                                     top[:, None])  # (P, K)
    caps = _POINT_CAPSULE
    u = np.where(_FIXED, _POINT_FRACTION, u)
    points = start[caps] + u[..., None] * (end - start)[caps]
    sep = axis_dist - radii[caps] - r_person[:, None]
    # n: the unit vector from each point to the nearest point of the person's axis
    nearest = bottom[:, None] + t_col[..., None] * (top - bottom)[:, None]
    inside = ~(axis_dist > 1e-9)
    n = np.where(inside[..., None], 0.0,
                 (nearest - points) / np.where(inside, 1.0, axis_dist)[..., None])
    nodes_v = node_velocities(arm, q, qd)
    velocity = (1.0 - u[..., None]) * nodes_v[_FIRST] + u[..., None] * nodes_v[_LAST]
    speed = np.sqrt(np.einsum('pkc,pkc->pk', velocity, velocity))
    v_r = np.where(inside, speed, np.maximum(np.einsum('pkc,pkc->pk', velocity, n), 0.0))
    toward = np.maximum(-np.einsum('pc,pkc->pk', v_person, n[..., :2]), 0.0)
    # the stopping distance: the farthest each point gets along n while the arm stops
    moved = _node_positions(arm, _stops(arm, q, qd, t_s)) - _node_positions(arm, q)
    along = ((1.0 - u) * np.einsum('mkc,pkc->mpk', moved[:, _FIRST], n)
             + u * np.einsum('mkc,pkc->mpk', moved[:, _LAST], n))
    s_s = np.maximum(along.max(axis=0), 0.0)
    c, t_r = params.constant, params.reaction_time
    reach = np.maximum(params.reach_speed, toward)
    v_h = approach_speed(np.maximum(params.walking_speed, toward), reach, params.reach_limit,
                         protective_separation(reach, v_r, t_r, t_s, s_s, c))
    scale, relaxed = allowed_scale(np.stack([sep, sep - params.hysteresis]), v_h, v_r, t_r,
                                   t_s, s_s, c)
    s_p = protective_separation(v_h, v_r, t_r, t_s, s_s, c)
    worst = np.unravel_index(int(np.argmin(scale + 1e-9 * (sep - s_p))), scale.shape)
    s = float(scale[worst])
    for _ in range(refine):
        if not 0.0 < s < 1.0:
            break
        at = _assess(arm, q, s * qd, bottom, top, v_person, r_person, params, labels, 0)
        if at.margin >= 0.0:
            break
        s *= at.scale ** 2   # twice the step to what the slowed velocity allows: lands safe
    cause = ''
    if s < 1.0:
        where = (f'{labels[worst[0]]} is {float(sep[worst]):.2f} m from {arm.name} '
                 f'{LINK_NAMES[caps[worst[1]]]}')
        if s <= 0.0:
            cause = (f'{where}, within S_p {float(v_h[worst] * t_r + c):.2f} m at standstill: '
                     'protective stop')
        else:
            cause = (f'{where}, S_p {float(s_p[worst]):.2f} m at full speed (directed '
                     f'{float(v_r[worst]):.2f} m/s): speed x {s:.2f}')
    return ArmSeparation(arm.name, float(sep.min()), float((sep - s_p).min()), s,
                         float(relaxed.min()), s <= 0.0, cause, t_s)


def allowed_along(arm: ArmModel, q: ArrayLike, qd: ArrayLike, persons: Sequence[Person],
                  params: SsmParams, ahead: Optional[ArrayLike] = None) -> float:
    """Return the least speed factor a planned move is allowed at the given samples of it.

    For a planner or a job that would rather choose work an arm can do at speed than work the
    monitor will slow: :func:`assess_arm` at each sample, the smallest factor (1 without
    persons). A preference, not the safety function: it weighs the quadratic's root without
    the monitor's check where the factor slows the arm (``refine=0``), a little above what the
    monitor may allow. The job's thresholds were set on it: with the check, inlet seeds 1 and
    2 sorted 112 and 114 (the job declined meetings just above ``person_speed``), without it
    115 and 117 (docs/people.md).

    :param q, qd: ``(M, 3)`` the move's joints and planned joint velocities at M samples.
    :param ahead: ``(M,)`` s from now to each sample, or None. Given, each sample is weighed
        against the persons where they are now and where they will be then if they keep
        their velocity (:func:`persons_ahead`): a person walking in is met where they are
        going, not where they were seen.

    >>> from scara_collab.core.config import load_config
    >>> from scara_collab.core.model import load_cell
    >>> arm, params = load_cell().leader, SsmParams.from_config(load_config('people'))
    >>> walker = Person(np.array([-3.0, -2.0]), np.array([1.5, 0.0]), 0.2, 1.8)
    >>> q, qd = [[2.6, 0.0, 0.0]], [[1.0, 0.0, 0.0]]   # the arm swings towards -x
    >>> allowed_along(arm, q, qd, [walker], params)      # the person 5 m from the base now
    1.0
    >>> allowed_along(arm, q, qd, [walker], params, ahead=[2.0])   # and 2 s on, 2 m
    0.0
    """
    if not persons:
        return 1.0
    q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
    if ahead is None:
        return min(assess_arm(arm, a, b, persons, params, 0).scale for a, b in zip(q, qd))
    return min(assess_arm(arm, a, b, tuple(persons) + persons_ahead(persons, dt), params,
                          0).scale
               for a, b, dt in zip(q, qd, np.asarray(ahead, dtype=float)))


def persons_ahead(persons: Sequence[Person], dt: float) -> Tuple[Person, ...]:
    """Return ``persons`` where they will be in ``dt`` s if they keep their velocity.

    >>> p = Person(np.array([1.0, 0.0]), np.array([0.5, -1.0]), 0.2, 1.8)
    >>> persons_ahead([p], 2.0)[0].position.tolist()
    [2.0, -2.0]
    """
    return tuple(replace(p, position=p.position + p.velocity * max(0.0, float(dt)))
                 for p in persons)


def braking_rate(arm: ArmModel, qd: ArrayLike) -> float:
    """Return how fast the factor may fall: ``1 / T_s`` of the planned joint velocities, 1/s.

    Lowering ``s`` at rate ``r`` changes each joint's speed by ``qd_j r`` per second (at a
    constant trajectory speed). At ``r = min_j a_j / |qd_j| = 1 / T_s`` no joint decelerates
    beyond its limit and the slowest-stopping joint decelerates at exactly its limit: from any
    ``s`` the arm is at rest after ``s T_s``, the stopping time :func:`assess_arm` counts
    (:func:`scara_collab.core.safety.stopping_time` of ``s qd``). ``inf`` for an arm at rest.

    >>> from scara_collab.core.model import load_cell
    >>> braking_rate(load_cell().leader, [2.0, 0.0, 0.0])   # 6 rad/s^2 / 2 rad/s
    3.0
    """
    t_s = safety.stopping_time(arm, qd)
    return math.inf if t_s <= 0.0 else 1.0 / t_s
