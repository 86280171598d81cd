"""Section 5, singularity: the documents' loop, pseudo-inverse and DLS, the planner's line."""
from pathlib import Path

import numpy as np

from benchmarks.claims import CLAIMS
from benchmarks.util import axes, finish, met, mm, num, Rows, table
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
#: the design documents' target 3.0 m from the shoulder axis (base frame)
FAR_TARGET = (3.0, 0.0, 0.4)


def study(arm: ArmModel, a, b, damping: float, threshold: float, dt: float) -> dict:
    """Run the design documents' loop along ``a`` -> ``b`` (base frame); ``damping`` 0: pinv."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    duration = float(np.linalg.norm(b - a)) / SPEED
    s = np.linspace(0.0, 1.0, int(round(duration / dt)) + 1)
    p_ref = base_to_world(arm, a + s[:, None] * (b - a))
    v_ref = np.broadcast_to((b - a) / duration, p_ref.shape)
    q0 = ik_both(arm, p_ref[0])[0]
    qd = resolved_rate(arm, q0, p_ref, v_ref, dt, gain=GAIN, dls_threshold=threshold,
                       dls_max_damping=damping)
    q = q0 + np.cumsum(qd, axis=0) * dt
    speed = np.abs(qd[:, :2]).max(axis=1)
    w = manipulability(arm, q)
    return {'peak_speed': float(speed.max()),
            'max_tool_error': float(np.linalg.norm(fk(arm, q) - p_ref, axis=1).max()),
            'min_manipulability': float(w.min()),
            'elbow_deg_at_min': float(np.degrees(abs(q[int(np.argmin(w)), 1]))),
            's': s, 'speed': speed}


def measure(smoke: bool, scratch: Path) -> dict:
    """Run every case with and without DLS, the planner's line and the two refusals."""
    arm = load_cell().leader
    cfg = load_config('controllers')['trajectory']
    threshold, damping = float(cfg['dls_threshold']), float(cfg['dls_max_damping'])
    dt = 0.01 if smoke else 0.001  # s: the differential-kinematics step
    cases = [{'name': name, 'pinv': study(arm, a, b, 0.0, threshold, dt),
              'dls': study(arm, a, b, damping, threshold, dt)} for name, (a, b) in CASES.items()]
    a, b = (base_to_world(arm, np.array(p)) for p in PLANNER_LINE)
    line = line_move(arm, ik(arm, a).unwrap(), b, dls_threshold=threshold,
                     dls_max_damping=damping)
    w = manipulability(arm, line.q)
    planner = {'peak_speed': float(np.abs(line.qd[:, :2]).max()),
               'min_manipulability': float(w.min()), 'damping_engaged': bool(w.min() < threshold),
               'max_elbow_deg': float(np.degrees(np.abs(line.q[:, 1]).max())),
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
            'far_target_result': 'accepted' if far.ok else far.reasons(),
            'velocity_limit': float(arm.max_velocity[0])}


def tables(sg: dict) -> list:
    """Return every study line both ways and the planner's line; the two refusals."""
    rows = [{'path': c['name'],
             'smallest manipulability': num(c['pinv']['min_manipulability'], 2, 'm²'),
             'elbow angle there': f'{c["pinv"]["elbow_deg_at_min"]:.1f}°',
             'peak speed, pseudo-inverse': num(c['pinv']['peak_speed'], 3, 'rad/s'),
             'peak speed, DLS': num(c['dls']['peak_speed'], 3, 'rad/s'),
             'off the line, pseudo-inverse': mm(c['pinv']['max_tool_error'], 2),
             'off the line, DLS': mm(c['dls']['max_tool_error'], 2),
             "design documents' claim":
                 CLAIMS['singularity'].figure if 'inner' in c['name'] else ''}
            for c in sg['cases']]
    pl = sg['planner']
    rows.append({'path': f'planner: time-optimal line {PLANNER_LINE[0]} → {PLANNER_LINE[1]} '
                 '(the closest inner graze the ±150° limit allows)',
                 'smallest manipulability': num(pl['min_manipulability'], 2, 'm²'),
                 'elbow angle there': f'{pl["max_elbow_deg"]:.1f}°',
                 'peak speed, DLS': f'{pl["peak_speed"]:.3g} rad/s ('
                 f'{"DLS engaged" if pl["damping_engaged"] else "no damping needed"})',
                 'off the line, DLS': f'{num(pl["max_deviation"], 2, "m")} (planned)'})
    refusals = [
        {'asked': 'the planner, the line into the inner circle',
         'answer': sg['planner_radial_inner'], "design documents' claim": ''},
        {'asked': "IK, the design documents' target 3.0 m from the shoulder axis",
         'answer': sg['far_target_result'],
         "design documents' claim": 'rejected the command immediately'}]
    return [table(rows, 'lrrrrrrl'), table(refusals)]


def summary(sg: dict) -> Rows:
    """Return the summary row: peak joint speed into the inner singularity, both ways."""
    case = sg['cases'][1]
    return [("peak joint speed into the inner singularity (design documents' loop)",
             CLAIMS['singularity'].figure,
             f'pseudo-inverse {case["pinv"]["peak_speed"]:.3g} rad/s, DLS '
             f'{case["dls"]["peak_speed"]:.3g} rad/s; planner ≤ '
             f'{sg["planner"]["peak_speed"]:.3g} rad/s', '≤ 2 rad/s',
             met(case['dls']['peak_speed'] <= sg['velocity_limit'] + 1e-9))]


def figure(sg: dict):
    """Peak revolute joint speed along each study path, pseudo-inverse vs DLS."""
    fig, (ax,) = axes(8.0, 3.6)
    for colour, case in zip(('tab:blue', 'tab:orange', 'tab:green'), sg['cases']):
        for kind, style, name in (('pinv', '--', 'pseudo-inverse'), ('dls', '-', 'DLS')):
            ax.plot(case[kind]['s'], case[kind]['speed'], style, color=colour,
                    label=f'{case["name"]}, {name}')
    ax.set_yscale('log')
    finish(ax, 'fraction of the path', 'fastest revolute joint (rad/s)',
           f"straight lines at {SPEED} m/s through the design documents' "
           'differential-kinematics loop',
           {sg['velocity_limit']: 'joint limit'})
    return fig
