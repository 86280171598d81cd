"""Section 6, collision foresight: conflicts of random crossing moves, found and resolved.

The measurement is :func:`scara_collab.bench.foresight.measure`; this module is its statistics,
summary row, Markdown (with the sorting jobs' separations, when section 7 ran them) and figure.
"""
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Dict, Iterable, List, Optional

import numpy as np

from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.util import (canvas, fmt_seconds, Log, m, md_table, met, num, plural,
                                     Progress, quote, Rows, save, Section, spread, usable)
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


def measure_pairs(n_pairs: int = 300, n_execute: int = 40, seed: int = 1, max_delay: float = 5.0,
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


@dataclass(frozen=True)
class Sizes:
    """How many crossing pairs are drawn, and how many of the conflicts run in physics."""

    foresight_pairs: int = 200
    foresight_execute: int = 30


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Draw, schedule and (some) execute the crossing pairs."""
    return measure_pairs(sizes.foresight_pairs, sizes.foresight_execute, log=progress.note)


def _median(values: Iterable[float]) -> Optional[float]:
    x = list(values)
    return float(np.median(x)) if x else None


def stats(data: dict) -> Dict[str, object]:
    """Return the figures of the study: conflicts, foresight, outcomes, delays, separations."""
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    executed = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    planned = [p['planned_min_m'] for p in pairs if p['planned_min_m'] is not None]
    return {
        'n': len(pairs), 'conflicts': len(conflicts),
        'touch': sum(p['impact_s'] is not None for p in conflicts),
        'foresight': spread(p['foresight_s'] for p in conflicts),
        'foresight_median': _median(p['foresight_s'] for p in conflicts),
        'impact': spread(p['impact_s'] for p in conflicts),
        'impact_median': _median(p['impact_s'] for p in conflicts if p['impact_s'] is not None),
        'outcomes': {k: sum(p['outcome'] == k for p in pairs)
                     for k in ('clear', 'delayed', 'waits')},
        'conflict_outcomes': {k: sum(p['outcome'] == k for p in conflicts)
                              for k in ('clear', 'delayed', 'waits')},
        'delay': spread(p['delay_s'] for p in conflicts if p['delay_s'] is not None),
        'delay_median': _median(p['delay_s'] for p in conflicts if p['delay_s'] is not None),
        'decision': spread(p['decision_s'] for p in pairs),
        'decision_median': _median(p['decision_s'] for p in pairs),
        'unresolved': spread(p['unresolved_min_m'] for p in conflicts),
        'planned': spread(planned),
        'executed': spread(executed),
        'planned_breaches': sum(v < data['margin'] for v in planned),
        'executed_breaches': sum(v < data['margin'] for v in executed),
    }


def summary(f: dict) -> Rows:
    """Return the summary row: conflicts found, how early, breaches planned and executed."""
    st = stats(f)
    return [('collision foresight (crossing pairs)', CLAIMS['foresight'].figure,
             f'{st["conflicts"]} conflicts in {st["n"]} pairs, all found at the decision,'
             f' {num(st["foresight"]["min"], 2, "s")} (min) before the margin would '
             f'break; {st["executed_breaches"]} breaches in {st["executed"]["n"]} '
             'executed', 'resolved at planning time; zero breaches',
             met(st['planned_breaches'] == 0 and st['executed_breaches'] == 0))]


def markdown(f: dict, results: dict) -> str:
    """Return the section's text: the claims, the study's figures, the jobs' separations."""
    st = stats(f)
    co, oc = st['conflict_outcomes'], st['outcomes']
    rows = [
        ('crossing pairs drawn', f'{st["n"]}', ''),
        (f'conflicts (closer than the {m(f["margin"], 2)} margin if started together)',
         f'{st["conflicts"]} ({st["touch"]} would touch)', ''),
        ('when a conflict is found', 'at the decision, before either arm moves (t = 0)',
         CLAIMS['foresight'].figure),
        ('decision → margin would break: min / median / max',
         f'{num(st["foresight"]["min"], 3, "s")} / {num(st["foresight_median"], 3, "s")} / '
         f'{num(st["foresight"]["max"], 3, "s")}', '200 ms before impact'),
        ('decision → capsules would touch: min / median',
         f'{num(st["impact"]["min"], 3, "s")} / {num(st["impact_median"], 3, "s")}', ''),
        ('motion starts after the decision (start lead)', num(f['lead'], 3, 's'), ''),
        ('conflicts resolved by delaying the right arm / the left arm never delayed / '
         'unresolvable (the follower waits)',
         f'{co["delayed"]} / {co["clear"]} / {co["waits"]}', ''),
        ('all pairs: clear / delayed (incl. the planning buffer) / waits',
         f'{oc["clear"]} / {oc["delayed"]} / {oc["waits"]}', ''),
        ('delay applied to conflicting pairs: median / max',
         f'{num(st["delay_median"], 3, "s")} / {num(st["delay"]["max"], 3, "s")}', ''),
        ('scheduling wall time per pair: median / max',
         f'{fmt_seconds(st["decision_median"])} / {fmt_seconds(st["decision"]["max"])}', ''),
        ('conflicting pairs started together: smallest distance, min / mean',
         f'{m(st["unresolved"]["min"])} / {m(st["unresolved"]["mean"])}', ''),
        ('every pair as scheduled (planned): smallest distance, min / mean',
         f'{m(st["planned"]["min"])} / {m(st["planned"]["mean"])}; breaches '
         f'{st["planned_breaches"]}', 'near-zero risk'),
        (f'conflicting pairs executed in physics with their delays ({st["executed"]["n"]}): '
         'smallest measured distance, min / mean',
         f'{m(st["executed"]["min"])} / {m(st["executed"]["mean"])}; breaches '
         f'{st["executed_breaches"]}', ''),
    ]
    t = results.get('throughput')
    if usable(t):
        seps = [r['min_separation_m'] for r in t['runs'] if r.get('mode') != 'single'
                and r.get('min_separation_m') is not None]
        if t.get('mirrored') and t['mirrored'].get('min_separation_m') is not None:
            seps.append(t['mirrored']['min_separation_m'])
        if seps:
            rows.append((f'sorting jobs with both arms ({plural(len(seps), "run")}, section 7): '
                         'smallest separation, min / mean',
                         f'{m(min(seps))} / {m(float(np.mean(seps)))}; breaches '
                         f'{sum(s < f["margin"] for s in seps)}', ''))
    return '\n\n'.join([
        quote('foresight', 'collision_risk'),
        f'{st["n"]} random pairs of crossing moves (seed {f["seed"]}): each arm between two '
        'random reachable points of its side and the shared zone, the tool paths crossing in '
        'plan view, the resting poses compatible (so a delay can always resolve a conflict). '
        f'Both moves are decided at t = 0 and asked to start at t = {f["lead"]:g} s, planned '
        'and scheduled by the motion core exactly as the planner nodes do (left has priority; '
        'the right arm waits the smallest delay, 10 ms resolution, that keeps '
        f'{m(f["planning_margin"], 2)}: the margin plus the planners\' buffer). Distances are '
        f'predicted on a {f["grid_s"] * 1e3:g} ms grid. The first {f["n_execute"]} conflicting '
        'pairs are then executed in physics with their delays and the separation is measured '
        'from the simulated joint states.',
        md_table(('what', 'measured', "seeds' claim"), rows),
        "The seeds' 200 ms is a detection before impact while moving; here a conflict is "
        'found when the moves are planned, before either starts, and resolved then (the '
        f'follower starts later). Margin breaches: {st["planned_breaches"]} planned, '
        f'{st["executed_breaches"]} executed in physics. The collision monitor (runtime '
        'e-stop below the margin) is the safety net behind this.'])


def figure(data: dict, path: Path) -> None:
    """Foresight of the conflicts found; separations unresolved, planned and executed."""
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    fig, (ax, ax2) = canvas(9.5, 3.6, 2)
    if conflicts:
        ax.hist([p['foresight_s'] for p in conflicts], bins=20, color='tab:blue', alpha=0.7,
                label='margin broken (predicted)')
        impacts = [p['impact_s'] for p in conflicts if p['impact_s'] is not None]
        if impacts:
            ax.hist(impacts, bins=20, color='tab:red', alpha=0.5, label='capsules touch')
    ax.axvline(0.2, color='k', ls='--', lw=1)
    ax.text(0.21, ax.get_ylim()[1] * 0.9, 'seeds: 200 ms', fontsize=7)
    ax.axvline(data['lead'], color='0.5', ls=':', lw=1)
    ax.text(data['lead'] + 0.01, ax.get_ylim()[1] * 0.8, 'motion starts', fontsize=7,
            color='0.4')
    ax.set_xlabel('time after the decision (s)')
    ax.set_ylabel('conflicting pairs')
    ax.set_title(f'{len(conflicts)} conflicts in {len(pairs)} crossing pairs', fontsize=10)
    ax.legend(fontsize=7)
    bins = np.linspace(-0.12, 0.42, 55)
    un = [p['unresolved_min_m'] for p in pairs if p['conflict']]
    pl = [p['planned_min_m'] for p in pairs if p['conflict'] and p['planned_min_m'] is not None]
    ex = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    for vals, colour, label in ((un, 'tab:red', 'started together (no resolution)'),
                                (pl, 'tab:blue', 'with the delay, planned'),
                                (ex, 'tab:green', 'with the delay, executed in physics')):
        if vals:
            ax2.hist(np.clip(vals, bins[0], bins[-1]), bins=bins, color=colour, alpha=0.55,
                     label=label)
    ax2.axvline(data['margin'], color='k', lw=1)
    ax2.text(data['margin'], ax2.get_ylim()[1] * 0.9, ' margin', fontsize=7)
    ax2.set_xlabel('smallest arm-to-arm distance over the pair (m)')
    ax2.set_ylabel('pairs')
    ax2.set_title('separation of the conflicting pairs', fontsize=10)
    ax2.legend(fontsize=7)
    save(fig, path)


SECTION = Section(
    key='foresight', title='collision foresight on crossing moves',
    heading='Collision foresight and margins', measure=measure, markdown=markdown,
    summary=summary, figure=figure, figure_alt='foresight and separation histograms',
    full=Sizes(), smoke=Sizes(foresight_pairs=6, foresight_execute=2))
