"""Section 6, collision foresight: conflicts of random crossing moves, found and resolved."""
from pathlib import Path
import time

import numpy as np

from benchmarks.claims import CLAIMS
from benchmarks.util import axes, finish, fmt_seconds, met, num, Rows, spread, table
from scara_collab.core import collision
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import ik, IKError
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.planning import plan_path, schedule, Timeline
from scara_collab.core.trajectory import interp_rows
from scara_collab.sim.cell_sim import CellSim

GRID = 0.005  # s: time grid on which the predicted separation is evaluated
MAX_DELAY = 5.0  # s: the longest delay tried (the moves last 1-2 s)


def _cross(a0, a1, b0, b1) -> bool:
    """Return True if the plan-view (x, y) segments ``a0-a1`` and ``b0-b1`` intersect."""
    def side(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))
    return side(a0, a1, b0) != side(a0, a1, b1) and side(b0, b1, a0) != side(b0, b1, a1)


def random_pair(cell: CellModel, rng: np.random.Generator, clearance: float):
    """Draw and plan two moves crossing in plan view that only their timing can bring together."""
    left, right = cell.leader, cell.follower

    def draw(y_lo, y_hi):
        return np.array([rng.uniform(1.0, 3.0), rng.uniform(y_lo, y_hi), rng.uniform(0.3, 0.45)])

    while True:
        ls, lg, rs, rg = draw(-1.5, 0.45), draw(-1.5, 0.45), draw(-0.45, 1.5), draw(-0.45, 1.5)
        if min(np.linalg.norm(lg - ls), np.linalg.norm(rg - rs)) < 0.4 \
                or not _cross(ls, lg, rs, rg):
            continue
        ql, qr = ik(left, ls), ik(right, rs)
        if not (ql.ok and qr.ok) or collision.arm_distance(left, ql.q, right, qr.q) < clearance:
            continue
        gl, gr = ik(left, lg, q_current=ql.q), ik(right, rg, q_current=qr.q)
        if not (gl.ok and gr.ok) or collision.arm_distance(left, gl.q, right, gr.q) < clearance:
            continue  # (a joint move ends there; a line may end on the other elbow)
        try:
            traj_l = plan_path(left, ql.q, lg, mode='line_or_joint')
            traj_r = plan_path(right, qr.q, rg, mode='line_or_joint')
        except IKError:
            continue
        if min(collision.arm_distance(left, traj_l.q[[0, -1]], right, traj_r.q[[0, -1]]).min(),
               collision.arm_distance(left, traj_l.q, right, traj_r.q[0]).min(),
               collision.arm_distance(left, traj_l.q[-1], right, traj_r.q).min()) >= clearance:
            return traj_l, traj_r


def _execute(sim: CellSim, cell: CellModel, moves) -> float:
    """Run ``[(Trajectory, start s)]`` of both arms in physics; return the least separation."""
    t0 = sim.time
    for arm, (traj, _) in zip(cell.arms, moves):  # both at their starts before either is sent:
        sim.reset_arm(arm.name, traj.q[0])  # the door checks a move against the other arm
    for arm, (traj, start) in zip(cell.arms, moves):
        sim.execute(arm.name, t0 + start + traj.t, traj.q, traj.qd, traj.qdd)
    end = t0 + max(start + traj.duration for traj, start in moves) + 0.2
    q = []
    while sim.time < end:
        q.append([sim.arm_state(arm.name)[0] for arm in cell.arms])
        sim.step(5)
    q = np.array(q)
    return float(collision.arm_distance(cell.leader, q[:, 0], cell.follower, q[:, 1]).min())


def measure(smoke: bool, scratch: Path) -> dict:
    """Draw, schedule and predict 200 crossing pairs (smoke: 6); execute the first 30 conflicts."""
    cell = load_cell()
    left, right = cell.leader, cell.follower
    margin = cell.safety_margin
    plan_margin = margin + float(load_config('controllers')['planning_buffer'])
    lead = float(load_config('automation')['decision_lead'])
    rng = np.random.default_rng(1)
    pairs = []
    with CellSim(cell, dict(load_config('simulation'), feed_interval=0.0)) as sim:
        n_pairs, n_execute = (6, 2) if smoke else (200, 30)
        while len(pairs) < n_pairs:
            traj_l, traj_r = random_pair(cell, rng, plan_margin + 0.02)
            t0 = time.perf_counter()
            plan_l = schedule(left, traj_l, lead, right, Timeline.hold(0.0, traj_r.q[0]),
                              plan_margin, leader=True, max_delay=MAX_DELAY)
            plan_r = plan_l and schedule(right, traj_r, lead, left, plan_l.timeline,
                                         plan_margin, leader=False, max_delay=MAX_DELAY)
            decide = time.perf_counter() - t0
            t = np.arange(0.0, lead + max(traj_l.duration, traj_r.duration) + 0.5 + GRID, GRID)
            d = collision.arm_distance(left, interp_rows(t, lead + traj_l.t, traj_l.q), right,
                                       interp_rows(t, lead + traj_r.t, traj_r.q))
            below, touch = np.nonzero(d < margin)[0], np.nonzero(d <= 0.0)[0]
            rec = {'conflict': bool(below.size), 'unresolved_min_m': float(d.min()),
                   'foresight_s': float(t[below[0]]) if below.size else None,
                   'impact_s': float(t[touch[0]]) if touch.size else None,
                   'decision_s': decide, 'outcome': 'waits', 'delay_s': None,
                   'planned_min_m': None, 'executed_min_m': None}
            if plan_r:
                rec['delay_s'] = plan_r.delay
                rec['outcome'] = 'delayed' if plan_r.delay > 0 or plan_l.delay > 0 else 'clear'
                rec['planned_min_m'] = collision.trajectory_min_distance(
                    left, plan_l.start + traj_l.t, traj_l.q, right, plan_r.start + traj_r.t,
                    traj_r.q)[0]
                done = sum(p['executed_min_m'] is not None for p in pairs)
                if rec['conflict'] and done < n_execute:
                    rec['executed_min_m'] = _execute(sim, cell, [(traj_l, plan_l.start),
                                                                 (traj_r, plan_r.start)])
            pairs.append(rec)
    return {'pairs': pairs, 'margin': margin, 'lead': lead, 'n_pairs': len(pairs)}


def _values(f: dict, key: str, conflicts: bool = True) -> dict:
    return spread(p[key] for p in f['pairs'] if p['conflict'] or not conflicts)


def _of(s: dict, keys: str, unit: str = 's') -> str:
    """Format the :func:`spread` ``s`` at ``keys`` ('min median'): ``'0.1 s / 0.2 s'``."""
    return ' / '.join(fmt_seconds(s[k]) if unit == 'wall' else num(s[k], 3, unit)
                      for k in keys.split())


def tables(f: dict) -> list:
    """Return the study's figures: conflicts, foresight, outcomes, delays, separations."""
    pairs, margin = f['pairs'], f['margin']
    conflicts = [p for p in pairs if p['conflict']]
    ahead, impact, delay = (_values(f, k) for k in ('foresight_s', 'impact_s', 'delay_s'))
    decision, together = _values(f, 'decision_s', False), _values(f, 'unresolved_min_m')
    planned, executed = _values(f, 'planned_min_m', False), _values(f, 'executed_min_m', False)

    def outcomes(group):
        return ' / '.join(str(sum(p['outcome'] == k for p in group))
                          for k in ('delayed', 'clear', 'waits'))

    def breaches(key):
        return sum(p[key] is not None and p[key] < margin for p in pairs)
    rows = [
        ('crossing pairs drawn', len(pairs), ''),
        (f'conflicts (closer than the {margin:g} m margin if started together)',
         f'{len(conflicts)} ({impact["n"]} would touch)', ''),
        ('when a conflict is found', 'at the decision, before either arm moves (t = 0)',
         CLAIMS['foresight'].figure),
        ('decision → margin would break: min / median / max', _of(ahead, 'min median max'),
         '200 ms before impact'),
        ('decision → capsules would touch: min / median', _of(impact, 'min median'), ''),
        ('motion starts after the decision (start lead)', num(f['lead'], 3, 's'), ''),
        ('conflicts: delayed / clear / unresolvable (the follower waits)', outcomes(conflicts),
         ''),
        ('all pairs: delayed (incl. the planning buffer) / clear / waits', outcomes(pairs), ''),
        ('delay applied to conflicting pairs: median / max', _of(delay, 'median max'), ''),
        ('scheduling wall time per pair: median / max', _of(decision, 'median max', 'wall'), ''),
        ('conflicting pairs started together: smallest distance, min / mean',
         _of(together, 'min mean', 'm'), ''),
        ('every pair as scheduled (planned): smallest distance, min / mean',
         f'{_of(planned, "min mean", "m")}; breaches {breaches("planned_min_m")}',
         'near-zero risk'),
        (f'conflicting pairs executed in physics with their delays ({executed["n"]}): smallest '
         f'measured distance, min / mean', f'{_of(executed, "min mean", "m")}; breaches '
         f'{breaches("executed_min_m")}', '')]
    return [table([{'what': w, 'measured': v, "design documents' claim": c} for w, v, c in rows])]


def summary(f: dict) -> Rows:
    """Return the summary row: conflicts found, how early, breaches planned and executed."""
    pairs = f['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    executed, planned = ([p[k] for p in pairs if p[k] is not None]
                         for k in ('executed_min_m', 'planned_min_m'))
    breaches = sum(v < f['margin'] for v in planned + executed)
    return [('collision foresight (crossing pairs)', CLAIMS['foresight'].figure,
             f'{len(conflicts)} conflicts in {len(pairs)} pairs, all found at the decision, '
             f'{num(_values(f, "foresight_s")["min"], 2, "s")} (min) before the margin would '
             f'break; {sum(v < f["margin"] for v in executed)} breaches in {len(executed)} '
             'executed', 'resolved at planning time; zero breaches', met(breaches == 0))]


def figure(f: dict):
    """Foresight of the conflicts found; separations unresolved, planned and executed."""
    conflicts = [p for p in f['pairs'] if p['conflict']]
    fig, (ax, ax2) = axes(9.5, 3.6, 2)
    for key, colour, label in (('foresight_s', 'tab:blue', 'margin broken (predicted)'),
                               ('impact_s', 'tab:red', 'capsules touch')):
        ax.hist([p[key] for p in conflicts if p[key] is not None], bins=20, color=colour,
                alpha=0.6, label=label)
    ax.axvline(0.2, color='k', ls='--', lw=1, label="design documents' 200 ms")
    ax.axvline(f['lead'], color='0.5', ls=':', lw=1, label='motion starts')
    finish(ax, 'time after the decision (s)', 'conflicting pairs',
           f'{len(conflicts)} conflicts in {len(f["pairs"])} crossing pairs')
    bins = np.linspace(-0.12, 0.42, 55)
    for key, colour, label in (('unresolved_min_m', 'tab:red', 'started together'),
                               ('planned_min_m', 'tab:blue', 'with the delay, planned'),
                               ('executed_min_m', 'tab:green', 'with the delay, executed')):
        vals = [p[key] for p in conflicts if p[key] is not None]
        ax2.hist(np.clip(vals, bins[0], bins[-1]), bins=bins, color=colour, alpha=0.55,
                 label=label)
    ax2.axvline(f['margin'], color='k', lw=1, label='margin')
    finish(ax2, 'smallest arm-to-arm distance over the pair (m)', 'pairs',
           'separation of the conflicting pairs')
    return fig
