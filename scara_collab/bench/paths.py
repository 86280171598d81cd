"""Path deviation: the straight Cartesian line vs joint interpolation, planned and executed.

The seeds' "1.5 m move from the rest position to the conveyor center" (seeds/000 §9.1) is
planned both ways by the motion core (both time-optimal under the same joint limits) and each
plan is executed in the PyBullet cell (:class:`~scara_collab.sim.cell_sim.CellSim`, the
controller of ``controllers.yaml``), measured from the joint states at the 100 Hz state rate.
Metrics (:func:`scara_collab.core.trajectory.path_metrics`, the same function for the plan
and the execution): largest distance of the tool from the straight segment, path length,
duration, peak joint speed, RMS tool jerk (third difference at 100 Hz: smoothness).
"""
import time
from typing import Dict, Optional

import numpy as np

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import ArmModel, CellModel, load_cell
from scara_collab.core.trajectory import (
    joint_move, line_move, path_metrics, segment_deviation, Trajectory)
from scara_collab.sim.cell_sim import CellSim

ARRIVED = 1e-3  # m: an executed move has arrived once the tool stays this close to the goal
SEEDS_MOVE = (np.array([3.2, -0.9, 0.4]), np.array([2.0, 0.0, 0.4]))
"""The seeds' 1.5 m move, world frame (left arm): from a rest pose (tool 1.5 m from the
shoulder axis) to the conveyor centre line, 1.5 m long."""


def plan(arm: ArmModel, start=SEEDS_MOVE[0], goal=SEEDS_MOVE[1]) -> Dict[str, object]:
    """Plan ``start`` -> ``goal`` as a straight line and as a joint move.

    :return: ``{'line': Trajectory, 'joint': Trajectory, 'line_plan_time_s': float,
        'joint_plan_time_s': float}``.
    """
    qa = ik(arm, start).unwrap()
    qb = ik(arm, goal, q_current=qa).unwrap()
    t0 = time.perf_counter()
    line = line_move(arm, qa, goal)
    t1 = time.perf_counter()
    joint = joint_move(arm, qa, qb)
    t2 = time.perf_counter()
    return {'line': line, 'joint': joint, 'line_plan_time_s': t1 - t0,
            'joint_plan_time_s': t2 - t1}


def execute(cell: CellModel, arm: ArmModel, traj: Trajectory, settle: float = 0.3,
            control_mode: Optional[str] = None) -> Dict[str, object]:
    """Execute ``traj`` on ``arm`` in a fresh simulator; sample the state every ``traj`` step.

    :param settle: sim seconds observed after the trajectory ends.
    :return: ``{'traj': measured Trajectory (t from the start), 'reference': planned joint
        positions at the same times, 'tracking_error': (N,) tool distance from the planned
        tool, m}``.
    """
    sim_cfg = dict(load_config('simulation'), feed_interval=0.0)
    with CellSim(cell, sim_cfg, control_mode=control_mode) as sim:
        sim.reset_arm(arm.name, traj.q[0])
        t0 = sim.time
        sim.execute(arm.name, t0 + traj.t, traj.q, traj.qd, traj.qdd)
        every = max(1, int(round(float(np.median(np.diff(traj.t))) / sim.dt)))
        n = int(np.ceil((traj.duration + settle) / (every * sim.dt)))
        t, q, qd = np.empty(n + 1), np.empty((n + 1, 3)), np.empty((n + 1, 3))
        for k in range(n + 1):
            t[k] = sim.time - t0
            q[k], qd[k] = sim.arm_state(arm.name)
            sim.step(every)
    qdd = np.gradient(qd, t, axis=0)
    measured = Trajectory(t=t, q=q, qd=qd, qdd=qdd, p=fk(arm, q))
    reference = traj.sample(t)
    return {'traj': measured, 'reference': reference,
            'tracking_error': np.linalg.norm(measured.p - fk(arm, reference), axis=1)}


def measure(cell: Optional[CellModel] = None, control_mode: Optional[str] = None,
            start=SEEDS_MOVE[0], goal=SEEDS_MOVE[1]) -> Dict[str, object]:
    """Plan and execute the move both ways; return the metrics and the paths for a figure.

    :return: ``{'start', 'goal', 'control_mode', 'planned': {method: metrics},
        'executed': {method: metrics + end and tracking errors}, 'plan_time_s': {...},
        (an executed ``duration`` is the time until the tool stays within :data:`ARRIVED`
        of the goal, None if it never does),
        'series': {method: {'planned_p', 'executed_t', 'executed_p', 'executed_deviation',
        'planned_t', 'planned_deviation'}}}`` (metrics as plain dicts, series as arrays).
    """
    cell = cell or load_cell()
    arm = cell.leader
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    plans = plan(arm, start, goal)
    mode = control_mode or load_config('controllers')['control_mode']
    out: Dict[str, object] = {
        'arm': arm.name, 'start': start.tolist(), 'goal': goal.tolist(),
        'length_m': float(np.linalg.norm(goal - start)), 'control_mode': mode,
        'plan_time_s': {'line': plans['line_plan_time_s'], 'joint': plans['joint_plan_time_s']},
        'planned': {}, 'executed': {}, 'series': {}}
    for method in ('line', 'joint'):
        traj = plans[method]
        run = execute(cell, arm, traj, control_mode=mode)
        done = run['traj']
        planned = path_metrics(traj, start, goal).as_dict()
        executed = path_metrics(done, start, goal).as_dict()
        executed['end_error'] = float(np.linalg.norm(done.p[-1] - goal))
        away = np.nonzero(np.linalg.norm(done.p - goal, axis=1) > ARRIVED)[0]
        executed['duration'] = float(done.t[away[-1] + 1]) if away.size and \
            away[-1] + 1 < len(done.t) else (0.0 if not away.size else None)
        executed['max_tracking_error'] = float(run['tracking_error'].max())
        out['planned'][method] = planned
        out['executed'][method] = executed
        out['series'][method] = {
            'planned_t': traj.t, 'planned_p': traj.p,
            'planned_deviation': segment_deviation(traj.p, start, goal),
            'executed_t': done.t, 'executed_p': done.p,
            'executed_deviation': segment_deviation(done.p, start, goal)}
    return out
