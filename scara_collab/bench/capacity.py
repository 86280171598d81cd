"""What bounds the sorting capacity: a single arm's cycle at the joint limits, line timing.

:func:`cycle_bound` times the single arm's cycle with the planners' own moves (from above a
bin down to an item on the belt and back); :func:`topp_ratios` times random straight lines
with the motion core and with TOPP-RA (``toppra``, an independent reference).
"""
import logging
from typing import Dict, List

import numpy as np

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import ik, IKError
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path
from scara_collab.core.sorting import drop_point, pick_height
from scara_collab.core.trajectory import line_move, Trajectory


def cycle_bound(step: float = 0.1) -> Dict[str, object]:
    """Time the leader's bin -> pick -> bin cycle over a grid of pick points.

    Pick points: the belt length in ``step`` (m) steps, across the items' lateral spread
    (``simulation.yaml`` ``lateral_jitter``) in 5 cm steps, at the job's pick height, where
    the arm reaches; each with both bins (the class mix). Moves are the planners'
    (``line_or_joint``, 10 ms samples) from and to the bin's drop point.

    :return: ``{'best_s', 'median_s', 'cases', 'items_per_min_best', 'items_per_min_median',
        'best_pick'}``: the cycle's motion time (no grasp, no release).
    """
    cell = load_cell()
    arm = cell.leader
    auto, sim = load_config('automation'), load_config('simulation')
    z = pick_height(cell, float(auto['pick_clearance']))
    belt = cell.belt
    jitter = float(sim['lateral_jitter'])
    ys = np.arange(belt.centre_y - jitter, belt.centre_y + jitter + 1e-9, 0.05)
    xs = np.arange(belt.x_start, belt.x_end + 1e-9, step)
    times: List[float] = []
    best = (np.inf, None)
    for cls in cell.item_classes:
        drop = drop_point(cell, arm.name, cls, float(auto['drop_clearance']))
        q_drop = ik(arm, drop).unwrap()
        for x in xs:
            for y in ys:
                pick = np.array([x, y, z])
                try:
                    there = plan_path(arm, q_drop, pick, mode='line_or_joint')
                    back = plan_path(arm, there.q[-1], drop, mode='line_or_joint')
                except (IKError, ValueError):
                    continue
                t = there.duration + back.duration
                times.append(t)
                if t < best[0]:
                    best = (t, pick)
    med = float(np.median(times))
    return {'best_s': float(best[0]), 'median_s': med, 'cases': len(times),
            'items_per_min_best': 60.0 / best[0], 'items_per_min_median': 60.0 / med,
            'best_pick': [float(v) for v in best[1]]}


def toppra_duration(arm, traj: Trajectory) -> float:
    """Return TOPP-RA's time along ``traj``'s own path (arc length), at the arm's limits."""
    import toppra
    from toppra import algorithm, constraint
    logging.getLogger('toppra').setLevel(logging.ERROR)
    d = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(traj.p, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(d) > 1e-9])
    path = toppra.SplineInterpolator(d[keep] / d[keep][-1], traj.q[keep])
    inst = algorithm.TOPPRA([constraint.JointVelocityConstraint(arm.max_velocity),
                             constraint.JointAccelerationConstraint(arm.max_acceleration)],
                            path, gridpoints=np.linspace(0.0, 1.0, 1001),
                            parametrizer='ParametrizeConstAccel')
    return inst.compute_trajectory().duration


def topp_ratios(n: int = 100, seed: int = 1) -> np.ndarray:
    """Line time / TOPP-RA time over ``n`` random lines (seeded) of at least 0.2 s."""
    arm = load_cell().leader
    rng = np.random.default_rng(seed)
    ratios: List[float] = []
    while len(ratios) < n:
        a, b = rng.uniform([0.8, -2.4, 0.25], [3.6, 0.3, 0.6], size=(2, 3))
        try:
            traj = line_move(arm, ik(arm, a).unwrap(), b)
        except (IKError, ValueError):
            continue
        if traj.duration >= 0.2:
            ratios.append(traj.duration / toppra_duration(arm, traj))
    return np.array(ratios)
