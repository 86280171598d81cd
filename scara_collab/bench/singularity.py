"""Singularities: the seeds' differential-kinematics loop with and without damping (DLS).

Kinematic studies (no physics): the tool is asked to run along a straight line at a constant
Cartesian speed and :func:`scara_collab.core.trajectory.resolved_rate` runs the seeds' loop at
1 kHz, ``q_dot = J^+ (v + K (p_ref - fk(q)))``, once with the plain pseudo-inverse and once
with the damped least squares of ``controllers.yaml`` (damping grows below manipulability
``dls_threshold``). Measured: the peak joint speed against the 2 rad/s limit, the tool's
largest distance from the line (what the damping costs), the smallest manipulability and the
largest elbow angle reached. The inner-circle cases need elbow angles beyond the arm's ±150°
limit: they test the solver where the seeds put their claim (θ2 ≈ 180°), not a move the cell
can make.

Beside them, what the planner does instead (:func:`scara_collab.core.trajectory.line_move`):
it times every path so that no joint exceeds its limit, and refuses lines into the inner
reach; and the IK on the seeds' 3.0 m target.
"""
from typing import Dict, Optional

import numpy as np

from scara_collab.bench.util import Log
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import base_to_world, fk, ik, ik_both, IKError, manipulability
from scara_collab.core.model import ArmModel, load_cell
from scara_collab.core.trajectory import line_move, resolved_rate, segment_deviation

SPEED = 0.3  # m/s along every study line
GAIN = 5.0   # 1/s, the loop's position feedback
CASES = {
    'inner circle, tangent graze at 0.505 m': ((0.6, 0.505, 0.4), (-0.6, 0.505, 0.4)),
    'inner circle, radial approach to 0.5005 m': ((1.2, 0.0, 0.4), (0.5005, 0.0, 0.4)),
    'outer circle, radial approach to 2.5 m': ((1.5, 0.0, 0.4), (2.5, 0.0, 0.4)),
}
"""Study lines in the arm's base frame (m): start and end of the tool path."""
PLANNER_LINE = ((1.0, 0.85, 0.4), (-1.0, 0.85, 0.4))
"""The closest tangent graze of the inner circle that the joint limits allow (base frame)."""
FAR_TARGET = (3.0, 0.0, 0.4)
"""The seeds' target 3.0 m from the shoulder axis (base frame)."""


def study(arm: ArmModel, a, b, damping: float, threshold: float, dt: float = 0.001,
          speed: float = SPEED) -> Dict[str, object]:
    """Run the seeds' loop along ``a`` -> ``b`` (base frame) at ``speed``.

    :param damping: the DLS ``max_damping`` (0 = plain pseudo-inverse).
    :return: ``{'peak_speed' (rad/s, the faster of the two revolute joints),
        'peak_speed_joint', 'max_tool_error' (m), 'min_manipulability' (m^2),
        'elbow_deg_at_min' (|theta2| where the manipulability is smallest), 'series': {'s',
        'speed'}}``.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    duration = float(np.linalg.norm(b - a)) / speed
    s = np.linspace(0.0, 1.0, int(round(duration / dt)) + 1)
    p_ref = base_to_world(arm, a + s[:, None] * (b - a))
    v_ref = np.broadcast_to((b - a) / duration, p_ref.shape)
    q0 = ik_both(arm, p_ref[0])[0]
    qd = resolved_rate(arm, q0, p_ref, v_ref, dt, gain=GAIN, dls_threshold=threshold,
                       dls_max_damping=damping)
    q = q0 + np.cumsum(qd, axis=0) * dt
    speed_abs = np.abs(qd[:, :2]).max(axis=1)
    w = manipulability(arm, q)
    return {'peak_speed': float(speed_abs.max()),
            'peak_speed_joint': int(np.argmax(np.abs(qd[:, :2]).max(axis=0))) + 1,
            'max_tool_error': float(np.linalg.norm(fk(arm, q) - p_ref, axis=1).max()),
            'min_manipulability': float(w.min()),
            'elbow_deg_at_min': float(np.degrees(abs(q[int(np.argmin(w)), 1]))),
            'series': {'s': s, 'speed': speed_abs}}


def measure(dt: float = 0.001, log: Optional[Log] = None) -> Dict[str, object]:
    """Run every case with and without DLS, the planner's line and the far target.

    :param dt: the loop period, s.
    """
    arm = load_cell().leader
    traj_cfg = load_config('controllers')['trajectory']
    threshold, damping = float(traj_cfg['dls_threshold']), float(traj_cfg['dls_max_damping'])
    cases = []
    for name, (a, b) in CASES.items():
        if log:
            log(name)
        cases.append({'name': name, 'start': list(a), 'end': list(b),
                      'pinv': study(arm, a, b, 0.0, threshold, dt),
                      'dls': study(arm, a, b, damping, threshold, dt)})
    a, b = (base_to_world(arm, np.array(p)) for p in PLANNER_LINE)
    q0 = ik(arm, a).unwrap()
    line = line_move(arm, q0, b, dls_threshold=threshold, dls_max_damping=damping)
    planner = {'line': [list(p) for p in PLANNER_LINE],
               'peak_speed': float(np.abs(line.qd[:, :2]).max()),
               'duration': line.duration,
               'mean_speed': float(np.linalg.norm(b - a) / line.duration),
               'min_manipulability': float(manipulability(arm, line.q).min()),
               'max_elbow_deg': float(np.degrees(np.abs(line.q[:, 1]).max())),
               'damping_engaged': bool(manipulability(arm, line.q).min() < threshold),
               'max_deviation': float(segment_deviation(line.p, a, b).max())}
    a, b = (base_to_world(arm, np.array(p)) for p in CASES[
        'inner circle, radial approach to 0.5005 m'])
    try:
        line_move(arm, ik(arm, a).unwrap(), b)
        refused = 'accepted'
    except IKError as exc:
        refused = str(exc)
    far = ik(arm, base_to_world(arm, np.array(FAR_TARGET)))
    return {'cases': cases, 'planner': planner, 'planner_radial_inner': refused,
            'far_target': list(FAR_TARGET),
            'far_target_result': 'accepted' if far.ok else far.reasons(),
            'speed': SPEED, 'gain': GAIN, 'dt': dt, 'dls_threshold': threshold,
            'dls_max_damping': damping, 'velocity_limit': float(arm.max_velocity[0])}
