"""The emergency stop's decisions, without ROS: when to stop, how to brake, what may move after.

A stop must come early enough that the arms, braking at their joint acceleration limits, stay
``margin`` apart. So the collision monitor does not wait for the measured distance to fall
below the margin: it predicts the distance along the trajectories the bridge was commanded
(:func:`first_breach`) and stops once that breach is nearer than the time the bridge needs to
stop the arms plus the watch's latency (:func:`stop_due`). The bridge then brakes every joint
at its acceleration limit (:func:`braking`), never harder. With the stop latched, a move that
only takes an arm away from the other one (:func:`separating`) may still run, so arms that
stopped too close can be parted and the stop cleared.

All times are absolute sim seconds; arms hold their first pose before a timeline starts and
their last pose after it ends (:class:`scara_collab.core.planning.Timeline`).
"""
from typing import Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core import collision
from scara_collab.core.model import ArmModel
from scara_collab.core.planning import Timeline

#: s: the prediction's time step (the planners' trajectory sample period / 2)
PREDICTION_STEP = 0.005


def stopping_time(arm: ArmModel, qd: ArrayLike) -> float:
    """Return how long braking from joint velocities ``qd`` takes at the acceleration limits."""
    return float(np.max(np.abs(np.asarray(qd, dtype=float)) / arm.max_acceleration))


def braking(arm: ArmModel, q: ArrayLike, qd: ArrayLike,
            dt: float = 0.01) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the stop from ``(q, qd)``: every joint decelerates at its limit to rest.

    :return: ``(t, q, qd, qdd)``: times from now (s, ``t[0] = 0``, at least two samples) and
        the joint positions, velocities and accelerations, each ``(N, 3)``; the last sample
        is at rest. Each joint stops after ``|qd| / max_acceleration``; none moves further
        than ``qd^2 / (2 max_acceleration)``.
    """
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    acc = -np.sign(qd) * arm.max_acceleration
    stop = np.abs(qd) / arm.max_acceleration
    t_end = max(float(stop.max()), dt)
    t = np.append(np.arange(0.0, t_end, dt), t_end)
    tau = np.minimum(t[:, None], stop[None, :])  # each joint moves only until it stops
    pos = q + qd * tau + 0.5 * acc * tau ** 2
    vel = qd + acc * tau
    accel = np.where(t[:, None] < stop[None, :], acc, 0.0)
    vel[-1] = 0.0
    accel[-1] = 0.0
    return t, pos, vel, accel


def first_breach(arm_a: ArmModel, a: Timeline, arm_b: ArmModel, b: Timeline, margin: float,
                 t_from: float, step: float = PREDICTION_STEP) -> Optional[float]:
    """Return the first time from ``t_from`` on that the arms come within ``margin``, or None.

    The timelines are followed to their ends (then held); the distance is evaluated every
    ``step`` seconds and at every stamp of either timeline.
    """
    t_end = max(a.end, b.end, t_from)
    grid = np.linspace(t_from, t_end, int(np.ceil((t_end - t_from) / step)) + 1)
    times = np.unique(np.concatenate([grid, a.t[(a.t > t_from) & (a.t < t_end)],
                                      b.t[(b.t > t_from) & (b.t < t_end)]]))
    close = collision.arm_distance(arm_a, a.at(times), arm_b, b.at(times)) < margin
    return float(times[np.argmax(close)]) if np.any(close) else None


def stop_due(now: float, breach: Optional[float], stopping: float, latency: float) -> bool:
    """Return True if the stop must come now to stay ahead of a predicted ``breach``.

    :param breach: the first predicted time within the margin (:func:`first_breach`), or None.
    :param stopping: the longer of the arms' :func:`stopping_time`, s.
    :param latency: s from a measured state to the bridge acting on the stop it causes (the
        state period plus the monitor's and the message's delays).

    With 0.2 s to stop and 0.05 s of latency, a breach 0.2 s ahead needs the stop now; one
    0.3 s ahead, or none, does not yet:

    >>> stop_due(1.0, 1.2, stopping=0.2, latency=0.05)
    True
    >>> stop_due(1.0, 1.3, stopping=0.2, latency=0.05), stop_due(1.0, None, 0.2, 0.05)
    (False, False)
    """
    return breach is not None and breach <= now + stopping + latency


def separating(arm: ArmModel, q_path: ArrayLike, other: ArmModel, q_other: ArrayLike,
               tolerance: float = 1e-4) -> bool:
    """Return True if moving ``arm`` along ``q_path`` never brings it nearer the other arm.

    The other arm holds ``q_other``. The distance may not drop below its starting value by
    more than ``tolerance`` anywhere on the path (sampled as given) and must end larger.
    """
    q_path = np.asarray(q_path, dtype=float).reshape(-1, 3)
    d = collision.arm_distance(arm, q_path, other, np.asarray(q_other, dtype=float))
    return bool(np.all(d >= d[0] - tolerance) and d[-1] > d[0])
