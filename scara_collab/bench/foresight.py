"""Collision foresight: how early conflicts between the arms are found, and how they end.

Random pairs of crossing moves (:func:`random_pair`: the two tool paths cross in plan view,
and the poses the arms rest in are compatible, so a delay can resolve any conflict). Both
moves are decided at ``t = 0`` and asked to start at ``t = lead`` (the automation manager's
``decision_lead``), planned as the planner nodes plan them
(:func:`scara_collab.core.planning.plan_path`) and scheduled as they schedule them
(:func:`scara_collab.core.planning.schedule`: left has priority, the right arm is delayed by
the smallest safe shift, keeping the cell's safety margin plus the planners' buffer).

Per pair: would the moves, started together, come closer than the margin (a conflict)? If so,
*foresight* = the predicted time the margin would first be broken minus the decision time,
and the time to impact (capsules touching) if they would touch. Then the delay the scheduler
applied, its wall time, and the minimum separation planned with the delay. The first
``n_execute`` conflicting pairs are executed in physics with their delays (both arms in one
:class:`~scara_collab.sim.cell_sim.CellSim`, the default controller) and the separation is
measured from the simulated joint states.
"""
import time
from typing import Dict, List, Optional

import numpy as np

from scara_collab.bench.util import Log
from scara_collab.core import collision
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import ik, IKError
from scara_collab.core.model import ArmModel, CellModel, load_cell
from scara_collab.core.planning import plan_path, schedule, Timeline
from scara_collab.core.trajectory import interp_rows, Trajectory
from scara_collab.sim.cell_sim import CellSim

PLANNING_BUFFER = float(load_config('controllers')['planning_buffer'])
"""m added to the safety margin when planning: the planner nodes' ``planning_buffer``
default."""
GRID = 0.005  # s: time grid on which the predicted separation is evaluated
SAMPLE_EVERY = 5  # physics steps between recorded states of an executed pair


def _segments_cross(a0, a1, b0, b1) -> bool:
    """Return ``True`` if the plan-view (x, y) segments ``a0-a1`` and ``b0-b1`` intersect."""
    def orient(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))
    return (orient(a0, a1, b0) != orient(a0, a1, b1)) and \
        (orient(b0, b1, a0) != orient(b0, b1, a1))


def random_pair(cell: CellModel, rng: np.random.Generator, clearance: float):
    """Draw and plan one crossing pair; return ``(points, left Trajectory, right Trajectory)``.

    Each arm moves between two random reachable points of its side of the cell and the
    shared zone (left ``-1.5 <= y <= 0.45``, right ``-0.45 <= y <= 1.5``, tool 0.3-0.45 m
    up), at least 0.4 m apart, planned as the planners do (straight line, or a joint move if
    the line is refused); the two tool paths cross in plan view. What a delay cannot change
    is kept ``clearance`` apart: both starts, both goals, the left move against the right arm
    resting at its start (the leader does not wait for it), the right move against the left
    arm resting at its goal (the follower can always go after the leader). Only the timing
    decides whether the pair conflicts.
    """
    left, right = cell.leader, cell.follower

    def draw(y_lo, y_hi):
        return np.array([rng.uniform(1.0, 3.0), rng.uniform(y_lo, y_hi),
                         rng.uniform(0.3, 0.45)])

    while True:
        ls, lg, rs, rg = draw(-1.5, 0.45), draw(-1.5, 0.45), draw(-0.45, 1.5), draw(-0.45, 1.5)
        if min(np.linalg.norm(lg - ls), np.linalg.norm(rg - rs)) < 0.4 \
                or not _segments_cross(ls, lg, rs, rg):
            continue
        sols = [ik(left, ls), ik(right, rs)]
        if not all(s.ok for s in sols) \
                or collision.arm_distance(left, sols[0].q, right, sols[1].q) < clearance:
            continue
        goals = [ik(left, lg, q_current=sols[0].q), ik(right, rg, q_current=sols[1].q)]
        if not all(s.ok for s in goals) \
                or collision.arm_distance(left, goals[0].q, right, goals[1].q) < clearance:
            continue  # (a joint move ends there; a line may end on the other elbow)
        try:
            traj_l = plan_path(left, sols[0].q, lg, mode='line_or_joint')
            traj_r = plan_path(right, sols[1].q, rg, mode='line_or_joint')
        except IKError:
            continue
        if min(collision.arm_distance(left, traj_l.q[[0, -1]], right, traj_r.q[[0, -1]]).min(),
               collision.arm_distance(left, traj_l.q, right, traj_r.q[0]).min(),
               collision.arm_distance(left, traj_l.q[-1], right, traj_r.q).min()) >= clearance:
            return (ls, lg, rs, rg), traj_l, traj_r


def _separation(left: ArmModel, tl: np.ndarray, ql: np.ndarray, right: ArmModel,
                tr: np.ndarray, qr: np.ndarray, t_end: float) -> Dict[str, np.ndarray]:
    """Predicted arm-to-arm distance on a :data:`GRID` from 0 to ``t_end`` (absolute times)."""
    times = np.arange(0.0, t_end + GRID, GRID)
    return {'t': times, 'd': collision.arm_distance(left, interp_rows(times, tl, ql), right,
                                                    interp_rows(times, tr, qr))}


def _schedule_pair(cell: CellModel, traj_l: Trajectory, traj_r: Trajectory, lead: float,
                   margin: float, max_delay: float):
    """Schedule both moves decided at t = 0 as the planners do; return the plans, wall s."""
    left, right = cell.leader, cell.follower
    t0 = time.perf_counter()
    plan_l = schedule(left, traj_l, lead, right, Timeline.hold(0.0, traj_r.q[0]), margin,
                      leader=True, max_delay=max_delay)
    plan_r = None if plan_l is None else schedule(right, traj_r, lead, left, plan_l.timeline,
                                                  margin, leader=False, max_delay=max_delay)
    return plan_l, plan_r, time.perf_counter() - t0


def _execute(sim: CellSim, cell: CellModel, traj_l: Trajectory, start_l: float,
             traj_r: Trajectory, start_r: float) -> float:
    """Run both moves in physics from rest; return the smallest measured separation, m."""
    left, right = cell.leader, cell.follower
    sim.reset_arm(left.name, traj_l.q[0])
    sim.reset_arm(right.name, traj_r.q[0])
    t0 = sim.time
    sim.execute(left.name, t0 + start_l + traj_l.t, traj_l.q, traj_l.qd, traj_l.qdd)
    sim.execute(right.name, t0 + start_r + traj_r.t, traj_r.q, traj_r.qd, traj_r.qdd)
    end = t0 + max(start_l + traj_l.duration, start_r + traj_r.duration) + 0.2
    ql, qr = [], []
    while sim.time < end:
        ql.append(sim.arm_state(left.name)[0])
        qr.append(sim.arm_state(right.name)[0])
        sim.step(SAMPLE_EVERY)
    return float(collision.arm_distance(left, np.array(ql), right, np.array(qr)).min())


def measure(n_pairs: int = 300, n_execute: int = 40, seed: int = 1, max_delay: float = 5.0,
            log: Optional[Log] = None) -> Dict[str, object]:
    """Run the study on ``n_pairs`` random crossing pairs; execute ``n_execute`` in physics.

    :param max_delay: the longest delay the scheduler tries, s (the moves last about 1-2 s;
        the planner nodes allow 30 s, which only matters when the other arm's resting pose
        blocks the way, a case :func:`random_pair` excludes).

    :return: ``{'pairs': [per pair dict], 'margin', 'planning_margin', 'lead', 'n_pairs',
        'n_execute', 'seed'}``; per pair: ``conflict``, ``foresight_s``, ``impact_s``,
        ``unresolved_min_m``, ``outcome`` (``'clear'``, ``'delayed'``, ``'waits'``: no delay
        keeps the margin, the follower waits), ``delay_s``, ``decision_s`` (wall),
        ``planned_min_m``, ``executed_min_m`` (or None).
    """
    cell = load_cell()
    left, right = cell.leader, cell.follower
    margin = cell.safety_margin
    plan_margin = margin + PLANNING_BUFFER
    lead = float(load_config('automation')['decision_lead'])
    rng = np.random.default_rng(seed)
    pairs: List[Dict[str, object]] = []
    executed = 0
    sim_cfg = dict(load_config('simulation'), feed_interval=0.0)
    with CellSim(cell, sim_cfg) as sim:
        while len(pairs) < n_pairs:
            (ls, lg, rs, rg), traj_l, traj_r = random_pair(cell, rng, plan_margin + 0.02)
            plan_l, plan_r, decide = _schedule_pair(cell, traj_l, traj_r, lead, plan_margin,
                                                    max_delay)
            t_end = lead + max(traj_l.duration, traj_r.duration) + 0.5
            pred = _separation(left, lead + traj_l.t, traj_l.q, right, lead + traj_r.t,
                               traj_r.q, t_end)
            below = np.nonzero(pred['d'] < margin)[0]
            touch = np.nonzero(pred['d'] <= 0.0)[0]
            rec: Dict[str, object] = {
                'left': [ls.tolist(), lg.tolist()], 'right': [rs.tolist(), rg.tolist()],
                'unresolved_min_m': float(pred['d'].min()), 'conflict': bool(below.size),
                'foresight_s': float(pred['t'][below[0]]) if below.size else None,
                'impact_s': float(pred['t'][touch[0]]) if touch.size else None,
                'decision_s': decide, 'delay_s': None, 'left_delay_s': None,
                'planned_min_m': None, 'executed_min_m': None}
            if plan_l is None or plan_r is None:
                rec['outcome'] = 'waits'
            else:
                rec['delay_s'], rec['left_delay_s'] = plan_r.delay, plan_l.delay
                rec['outcome'] = 'delayed' if plan_r.delay > 0 or plan_l.delay > 0 else 'clear'
                rec['planned_min_m'] = collision.trajectory_min_distance(
                    left, plan_l.start + traj_l.t, traj_l.q, right, plan_r.start + traj_r.t,
                    traj_r.q)[0]
                if rec['conflict'] and executed < n_execute:
                    rec['executed_min_m'] = _execute(sim, cell, traj_l, plan_l.start, traj_r,
                                                     plan_r.start)
                    executed += 1
            pairs.append(rec)
            if log and len(pairs) % max(1, n_pairs // 4) == 0:
                log(f'collision foresight: {len(pairs)}/{n_pairs} pairs, {executed} executed')
    return {'pairs': pairs, 'margin': margin, 'planning_margin': plan_margin, 'lead': lead,
            'n_pairs': n_pairs, 'n_execute': n_execute, 'seed': seed, 'grid_s': GRID,
            'max_delay': max_delay}
