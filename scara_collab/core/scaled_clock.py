"""A trajectory's own clock, run at a speed factor: ``tau' = s`` (speed scaling), no ROS.

An arm slowed by the separation monitor keeps its trajectory and runs it on a clock of its
own, as ros2_controllers' joint trajectory controller does with a speed scaling factor (UR's
scaled controller, CNR's scaled_fjt_controller): trajectory time ``tau`` advances ``s dt``
per ``dt`` of sim time, the reference is sampled at ``tau``, and by the chain rule::

    q_cmd   = q(tau)
    qd_cmd  = qd(tau) s
    qdd_cmd = qdd(tau) s^2 + qd(tau) s'

The trajectory is never changed, so the arm stays on its path at any ``s``; ``s = 0`` holds it
where it is on the path; when ``s`` returns the move continues from there, with no jump and no
race to catch up (``tau`` never runs ahead of what the arm did).

**How fast s may change.** ``s`` is the arm's speed along its path, ``s'`` adds
``qd(tau) s'`` to each joint's acceleration. With the trajectory within its limits at
``s = 1`` (``|qd| <= v_max``, ``|qdd| <= a_max``) and ``s`` in [0, 1] the velocities stay within
``s v_max``; the accelerations stay within ``a_max`` where, for every joint ``j`` that moves,

    -a_max_j <= qdd_j(tau) s^2 + qd_j(tau) s' <= a_max_j

an interval of ``s'`` that always holds 0 (:func:`rate_bounds`). :meth:`ScaledClock.tick`
moves ``s`` towards the factor asked for, at the fastest rate in that interval. Where the
trajectory does not accelerate (``qdd = 0``) the fastest fall is ``min_j a_max_j / |qd_j|``,
which stops the arm in :func:`scara_collab.core.safety.stopping_time` of its velocity ``T_s``.
Where the trajectory's own accelerations leave less room (a joint it brakes at its limit
already while another speeds up, as on a SCARA's straight lines) the fall is slower: on
planned lines the path-keeping stop takes 1.03 ``T_s`` at the median, 1.77 ``T_s`` at the 99th
percentile, 2.3 ``T_s`` at worst (``test_scaled_clock``). The separation monitor counts on a
stop within ``stop_allowance`` ``T_s`` (:class:`scara_collab.core.ssm.SsmParams`); the clock
holds the arm to it. From where a fall begins, the arm's stopping time at its limits must
fall at ``1 / stop_allowance`` per second of sim time (to what the factor asked allows), with
a slack of ``BRAKING_SLACK`` of the stopping time; an arm behind that profile is
:attr:`ScaledSample.held_back`, and must brake every joint at its limit instead
(:func:`scara_collab.core.safety.braking`: off the path, within its stopping time).

The clock takes the reference as a function ``sample(tau) -> (q, qd, qdd)``, e.g.
:meth:`scara_collab.sim.reference.HermiteReference.sample`, in the reference's own (absolute)
time: at ``s = 1`` throughout, ``tau`` is the sim time and the arm runs its trajectory as
planned; the lag ``t - tau`` is what the scaling cost.
"""
import math
from typing import Callable, NamedTuple, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

Sample = Tuple[np.ndarray, np.ndarray, np.ndarray]
#: How far the stopping time may be above the profile of its fall (a share of it) and still
#: keep up with it
BRAKING_SLACK = 0.1


class ScaledSample(NamedTuple):
    """The command at one tick.

    :ivar q, qd, qdd: ``(3,)`` the joints' position, velocity and acceleration.
    :ivar tau: the trajectory time sampled, s.
    :ivar scale: ``s`` at the tick; :ivar rate: ``s'`` over the step that ended there, 1/s.
    :ivar held_back: True if ``s`` was asked to fall and the arm's stopping time is above the
        profile of its fall (from the stopping time where it began, falling at
        ``1 / stop_allowance``) because the trajectory's own accelerations left no room: the
        path-keeping stop is then slower than the stop the separation monitor counts on, and
        the arm must brake instead (module docstring).
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: float
    scale: float
    rate: float
    held_back: bool = False


def rate_bounds(qd: np.ndarray, qdd: np.ndarray, scale: float,
                max_acceleration: np.ndarray) -> Tuple[float, float]:
    """Return the interval of ``s'`` that keeps ``|qdd s^2 + qd s'| <= a_max`` for every joint.

    :param qd, qdd: ``(3,)`` the trajectory's velocity and acceleration at ``tau``.
    :param scale: ``s``.
    :param max_acceleration: ``(3,)`` the joints' limits.
    :return: ``(low, high)``, 1/s; ``(-inf, inf)`` where no joint moves. If a joint is over
        its limit already at ``s' = 0`` (a trajectory over its limits), ``(0, 0)``.

    A joint at 2 rad/s, not accelerating, limited to 6 rad/s^2: ``s`` may change at 3 per
    second either way::

        >>> rate_bounds(np.array([2.0, 0, 0]), np.zeros(3), 1.0, np.full(3, 6.0))
        (-3.0, 3.0)
    """
    moving = np.abs(qd) > 1e-12
    if not np.any(moving):
        return -math.inf, math.inf
    v = qd[moving]
    base = qdd[moving] * scale * scale
    a = max_acceleration[moving]
    ends = np.stack([(-a - base) / v, (a - base) / v])
    low, high = float(ends.min(axis=0).max()), float(ends.max(axis=0).min())
    if low > high:
        return 0.0, 0.0
    return low, high


class ScaledClock:
    """One arm's trajectory clock (module docstring).

    :param time: the sim time it starts at, s (the trajectory time starts there too).
    :param max_velocity: ``(3,)`` joint velocity limits.
    :param max_acceleration: ``(3,)`` joint acceleration limits.
    :param scale: the factor it starts at.
    :param stop_allowance: the stop its slowdowns must keep up with, in stopping times at the
        joints' limits (at least 1; the separation monitor's, module docstring).

    A trajectory run at half speed has covered half its time, and its velocity is halved::

        >>> def ramp(tau):  # joint 1 at 1 rad/s from t = 0
        ...     return np.array([tau, 0, 0]), np.array([1.0, 0, 0]), np.zeros(3)
        >>> clock = ScaledClock(0.0, np.full(3, 2.0), np.full(3, 6.0), scale=0.5)
        >>> cmd = clock.tick(1.0, 0.5, ramp)
        >>> cmd.tau, float(cmd.qd[0]), clock.lag
        (0.5, 0.5, 0.5)
    """

    def __init__(self, time: float, max_velocity: ArrayLike, max_acceleration: ArrayLike,
                 scale: float = 1.0, stop_allowance: float = 1.0):
        """Start with ``tau = time`` at rest on the clock's own terms (``s' = 0``)."""
        if not stop_allowance >= 1.0:
            raise ValueError(f'stop_allowance must be at least 1, got {stop_allowance}')
        self.stop_allowance = float(stop_allowance)
        self.time = float(time)
        self.tau = float(time)
        self.scale = float(min(max(scale, 0.0), 1.0))
        self.rate = 0.0
        self.max_velocity = np.asarray(max_velocity, dtype=float)
        self.max_acceleration = np.asarray(max_acceleration, dtype=float)
        self._planned = np.zeros(3)
        self._fall = None  # (time, s, braking rate) where the current fall started

    @property
    def lag(self) -> float:
        """Sim time minus trajectory time, s: how far the scaling has set the arm back."""
        return self.time - self.tau

    @property
    def planned_velocity(self) -> np.ndarray:
        """The trajectory's velocity at ``tau`` as planned, unscaled, ``(3,)`` (last tick).

        What the separation monitor weighs an arm's speed by
        (:func:`scara_collab.core.ssm.assess_arm`): the arm runs at ``s`` times it.
        """
        return self._planned

    def full_speed(self) -> None:
        """Run at ``s = 1`` from now, at once (a brake: it is planned from the arm's state)."""
        self.scale, self.rate, self._fall = 1.0, 0.0, None

    @property
    def steady(self) -> bool:
        """True at full speed, no fall to keep up with: a tick to 1 changes nothing but time."""
        return self.scale == 1.0 and self._fall is None

    def coast(self, now: float) -> None:
        """Advance a :attr:`steady` clock to ``now`` as :meth:`tick` to 1 would, without sampling.

        The trajectory time runs with sim time; :attr:`planned_velocity` is not updated.

        :raises ValueError: if the clock is not steady or ``now`` is before the last tick.
        """
        dt = float(now) - self.time
        if dt < 0.0 or not self.steady:
            raise ValueError(f'cannot coast to {now} s from {self.time} s at s = {self.scale}')
        if dt > 0.0:
            self.rate = 0.0
            if self.tau == self.time:
                self.tau = float(now)
            else:
                self.tau += dt  # what tick adds at s = 1 (0.5 * (1 + 1) * dt), to the bit
        self.time = float(now)

    def restart(self, time: float) -> None:
        """Set the trajectory time to ``time`` (no lag), keeping ``s``: a new trajectory."""
        self.time = float(time)
        self.tau = float(time)

    def _rate(self, dt: float, target: float, sample: Callable[[float], Sample]) -> float:
        """Return the rate towards ``target`` over the next ``dt`` within the limits.

        The bounds of :func:`rate_bounds` hold at the step's start; the trajectory's velocity
        and acceleration change over the step (a time-optimal plan switches its accelerations
        between samples), so the bounds at the step's end, for the ``s`` and ``tau`` the rate
        leads to, are intersected too (twice: the end depends on the rate). Both hold 0.
        """
        _, qd, qdd = sample(self.tau)
        low, high = rate_bounds(qd, qdd, self.scale, self.max_acceleration)
        rate = min(max((target - self.scale) / dt, low), high)
        for _ in range(2):
            new = min(max(self.scale + rate * dt, 0.0), 1.0)
            _, qd, qdd = sample(self.tau + 0.5 * (self.scale + new) * dt)
            end_low, end_high = rate_bounds(qd, qdd, new, self.max_acceleration)
            low, high = max(low, end_low), min(high, end_high)
            if low > high:
                return 0.0
            rate = min(max(rate, low), high)
        return rate

    def feasible(self, now: float, target: float, sample: Callable[[float], Sample]) -> float:
        """Return the rate :meth:`tick` would take towards ``target`` up to ``now``, 1/s.

        Clocks that must run together (two arms scheduled against each other) each say theirs,
        and all take the one of smallest size: it lies within every clock's limits (each
        interval of :func:`rate_bounds` holds 0).
        """
        dt = float(now) - self.time
        target = min(max(float(target), 0.0), 1.0)
        if dt <= 0.0 or target == self.scale:
            return 0.0
        return self._rate(dt, target, sample)

    def tick(self, now: float, target: float,
             sample: Callable[[float], Sample], rate: Optional[float] = None) -> ScaledSample:
        """Advance to sim time ``now``, moving ``s`` towards ``target``; return the command.

        ``s`` moves towards ``target`` (clipped to [0, 1]) at the fastest rate
        :func:`rate_bounds` allows at the trajectory's state at the start and at the end of the
        step; ``tau`` advances by the mean of ``s`` over the step (exact for ``s`` linear in
        time). At a constant factor the reference is sampled once.

        :param now: sim time, s (not before the last tick).
        :param target: the factor asked for (the separation monitor's).
        :param sample: the reference, ``sample(tau) -> (q, qd, qdd)``.
        :param rate: the rate to take (clocks run together, :meth:`feasible`), within this
            clock's limits; None: this clock's own.
        :raises ValueError: if ``now`` is before the last tick.
        """
        dt = float(now) - self.time
        if dt < 0.0:
            raise ValueError(f'the clock cannot run backwards: {now} s after {self.time} s')
        target = min(max(float(target), 0.0), 1.0)
        held_back = False
        if dt > 0.0:
            if rate is None:
                rate = self._rate(dt, target, sample) if target != self.scale else 0.0
            new = min(max(self.scale + rate * dt, 0.0), 1.0)
            if target < self.scale and self._fall is None:  # a fall starts: what it promises
                self._fall = (self.time, self._stopping(sample(self.tau)[1] * self.scale))
            elif target >= self.scale:
                self._fall = None
            self.rate = (new - self.scale) / dt
            if self.tau == self.time and self.scale == new == 1.0:
                self.tau = float(now)  # on sim time: it stays there, to the bit
            else:
                self.tau += 0.5 * (self.scale + new) * dt
            self.scale = new
        self.time = float(now)
        q, qd, qdd = sample(self.tau)
        self._planned = np.asarray(qd, dtype=float)
        s = self.scale
        if self._fall is not None:
            t0, t_s0 = self._fall
            planned = self._stopping(self._planned)
            promised = max(target * planned,
                           t_s0 - (self.time - t0) / self.stop_allowance)
            held_back = s * planned > promised + BRAKING_SLACK * max(t_s0, planned)
        return ScaledSample(np.asarray(q, dtype=float), qd * s, qdd * s * s + qd * self.rate,
                            self.tau, s, self.rate, held_back)

    def _stopping(self, qd: np.ndarray) -> float:
        """Return the stopping time of joint velocities ``qd`` at the limits, s."""
        return float(np.max(np.abs(qd) / self.max_acceleration))
