"""Section 7, throughput: the job's capacity in one process and through the launcher; bounds."""
from dataclasses import dataclass
import logging
from pathlib import Path
import time
from typing import Dict, List, Sequence, Tuple

import numpy as np

from benchmarks.claims import CLAIMS
from benchmarks.job_in_process import default_feed, run_job
from benchmarks.launched import run_launcher
from benchmarks.payload import LINES
from benchmarks.util import axes, finish, met, num, Rows, spread, table
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import ik, IKError
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path
from scara_collab.core.sorting import drop_point, pick_height
from scara_collab.core.trajectory import line_move, Trajectory
from scara_collab.sim.cell_sim import CellSim

#: the design documents' capacity per mode, items/min
CLAIMED = {'single': 12.0, 'collaborative': 22.0}
SAME = ('sorted', 'missed', 'dropped', 'wrong_bin', 'give_ups', 'retries', 'min_separation_m',
        'min_separation_time')  # what "the same job result" compares, to the last bit


@dataclass(frozen=True)
class Sizes:
    """How long and how often the job runs (the capacity runs are most of the full run)."""

    job_seeds: Tuple[int, ...] = (1, 2, 3)
    job_modes: Tuple[str, ...] = ('single', 'collaborative', 'mirrored')
    job_duration: float = 240.0      # sim s per capacity run (shorter runs read low)
    capacity_feed: float = 1.0       # s per item: faster than the arms can take (~60/min)
    repeats: int = 3                 # collaborative, first seed: the same run this many times
    rated_duration: float = 600.0    # sim s of collaborative at the rated feed; 0 = none
    launcher_duration: float = 60.0  # sim s of each launcher run (processes, one process)
    launcher_repeats: int = 3        # launcher runs of each kind, same seed and flags
    cycle_step: float = 0.1          # m between pick points of the cycle bound
    topp_lines: int = 100            # random lines timed against TOPP-RA
    speed_items: Tuple[int, ...] = (0, 5, 10)  # items on the belt, simulator alone
    speed_modes: Tuple[str, ...] = ('computed_torque', 'pid')
    speed_seconds: float = 3.0       # sim s per simulator-alone run, median of speed_repeat
    speed_repeat: int = 3


SMOKE = Sizes(job_seeds=(1,), job_modes=('collaborative',), job_duration=8.0, repeats=1,
              rated_duration=0.0, launcher_duration=0.0, cycle_step=0.6, topp_lines=2,
              speed_items=(0,), speed_modes=('computed_torque',), speed_seconds=0.5,
              speed_repeat=1)


def cycle_bound(step: float = 0.1) -> Dict[str, object]:
    """Time the leader's bin -> pick -> bin moves (no grasp) over the belt in ``step`` m x 5 cm."""
    cell = load_cell()
    arm, belt = cell.leader, cell.belt
    auto, jitter = load_config('automation'), float(load_config('simulation')['lateral_jitter'])
    z = pick_height(cell, float(auto['pick_clearance']))
    ys = np.arange(belt.centre_y - jitter, belt.centre_y + jitter + 1e-9, 0.05)
    xs = np.arange(belt.x_start, belt.x_end + 1e-9, step)
    times, best = [], (np.inf, None)
    for cls in cell.item_classes:
        drop = drop_point(cell, arm.name, cls, float(auto['drop_clearance']))
        q_drop = ik(arm, drop).unwrap()
        for pick in (np.array([x, y, z]) for x in xs for y in ys):
            try:
                there = plan_path(arm, q_drop, pick, mode='line_or_joint')
                back = plan_path(arm, there.q[-1], drop, mode='line_or_joint')
            except (IKError, ValueError):
                continue
            times.append(there.duration + back.duration)
            best = min(best, (times[-1], pick), key=lambda b: b[0])
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


def sim_speed(mode: str, n_items: int, seconds: float) -> float:
    """Return the simulator's real-time factor, both arms shuttling along ``payload.LINES``."""
    cell = load_cell()
    with CellSim(cell, dict(load_config('simulation'), feed_interval=0.0),
                 control_mode=mode) as sim:
        ends = {arm.name: [ik(arm, np.array(p)).q for p in LINES[arm.name]] for arm in cell.arms}
        for arm in cell.arms:
            sim.reset_arm(arm.name, ends[arm.name][0])
        for k in range(n_items):
            sim.conveyor.spawn_item(x=cell.belt.x_start + 0.1 + 0.4 * k)
        steps, leg = int(round(seconds / sim.dt)), {name: 1 for name in ends}
        start = time.perf_counter()
        for _ in range(0, steps, 10):
            for arm in cell.arms:
                if not sim.active(arm.name):
                    q_now = sim.arm_state(arm.name)[0]
                    goal = ends[arm.name][leg[arm.name] % 2]
                    span = 1.5 * np.max(np.abs(goal - q_now) / (0.75 * arm.max_velocity))
                    sim.execute(arm.name, sim.time + np.array([0.0, max(span, 0.1)]),
                                [q_now, goal])
                    leg[arm.name] += 1
            sim.step(10)
        return steps * sim.dt / (time.perf_counter() - start)


def measure(smoke: bool, scratch: Path) -> dict:
    """Run the capacity runs, the repeats, the rated feed, the launcher, the bounds, the speed."""
    sizes = SMOKE if smoke else Sizes()
    feed, first = sizes.capacity_feed, sizes.job_seeds[0]
    runs = [run_job(mode, sizes.job_duration, feed=feed, seed=seed)
            for seed in sizes.job_seeds for mode in sizes.job_modes]
    repeats = [r for r in runs if r['mode'] == 'collaborative' and r['seed'] == first]
    repeats += [run_job('collaborative', sizes.job_duration, feed=feed, seed=first)
                for _ in range(1, sizes.repeats)]
    rated = run_job('collaborative', sizes.rated_duration, seed=first) \
        if sizes.rated_duration else None
    launcher_runs = {}
    for k in range(sizes.launcher_repeats if sizes.launcher_duration else 0):
        for name, flags in (('processes', ()), ('one_process', ('--one-process',))):
            launcher_runs.setdefault(name, []).append(run_launcher(
                'collaborative', sizes.launcher_duration, scratch / f'launcher_{name}_{k + 1}',
                seed=first, extra=flags))
    ratios = topp_ratios(sizes.topp_lines)
    speed = [{'items': n, 'mode': mode, 'seconds': sizes.speed_seconds,
              'rtf': float(np.median([sim_speed(mode, n, sizes.speed_seconds)
                                      for _ in range(sizes.speed_repeat)]))}
             for n in sizes.speed_items for mode in sizes.speed_modes]
    return {'runs': runs, 'repeats': repeats, 'rated': rated, 'launcher_runs': launcher_runs,
            'cycle': cycle_bound(step=sizes.cycle_step), 'topp': spread(ratios),
            'speed': speed, 'duration': sizes.job_duration, 'modes': list(sizes.job_modes),
            'feed_interval': feed, 'rated_feed': default_feed()}


def result_of(run: dict) -> tuple:
    """Return what :data:`SAME` compares (the launcher's summary keeps give-ups in ``job``)."""
    return tuple(run.get(k, (run.get('job') or {}).get(k)) for k in SAME)


def identical(runs: Sequence[dict]) -> bool:
    """Return True if every run finished and their job results agree to the last bit."""
    return all('error' not in r for r in runs) and len({result_of(r) for r in runs}) == 1


def launcher(t: dict, name: str) -> dict:
    """Return the launcher run of ``name`` of median real-time factor (``{}``: none)."""
    good = sorted((r for r in t['launcher_runs'].get(name, []) if 'error' not in r),
                  key=lambda r: r['real_time_factor'])
    return good[(len(good) - 1) // 2] if good else {}


def jobs(t: dict, mode: str) -> List[dict]:
    """Return the capacity runs of ``mode``."""
    return [r for r in t['runs'] if r['mode'] == mode]


def repeat_sets(t: dict) -> List[Tuple[str, List[dict]]]:
    """Return the repeated runs with their names: in one process, through the launcher."""
    sets = [(f'in one process (an item every {t["feed_interval"]:g} s, {t["duration"]:g} sim s)',
             t['repeats']),
            ('through the launcher, --one-process', t['launcher_runs'].get('one_process', [])),
            ('through the launcher, one process per node',
             t['launcher_runs'].get('processes', []))]
    return [(what, runs) for what, runs in sets if len(runs) > 1]


def _joined(runs: Sequence[dict], key: str) -> str:
    return ', '.join(num(r.get(key), 3) for r in runs)


def tables(t: dict) -> list:
    """Return capacity per mode, what bounds it, repeatability, real-time factor, CPU cost."""
    cap = []
    for mode in t['modes']:
        runs = jobs(t, mode)
        ipm = spread(r['items_per_minute'] for r in runs)
        cap.append({
            'mode': mode, 'seeds': ', '.join(str(r['seed']) for r in runs),
            'items/min mean ± sd (min–max)': f'{num(ipm["mean"])} ± {num(ipm["std"], 2)} '
            f'({num(ipm["min"])}–{num(ipm["max"])})',
            'sorted': _joined(runs, 'sorted'), 'give-ups': _joined(runs, 'give_ups'),
            'dropped + wrong bin': ', '.join(str(r['dropped'] + r['wrong_bin']) for r in runs),
            'min separation (m)': 'n/a' if mode == 'single' else _joined(runs, 'min_separation_m'),
            'e-stops': sum(bool(r['estop']) for r in runs),
            'real-time factor': num(np.mean([r['real_time_factor'] for r in runs]), 2),
            'in-step mirror error (mm)': ', '.join(num(r['mirror_error_max_m'] * 1e3, 3)
                                                   for r in runs) if mode == 'mirrored' else '',
            "design documents' claim": f'{CLAIMED[mode]:g} items/min' if mode in CLAIMED else ''})
    ratio, cyc, topp, rated = pair_ratio(t), t['cycle'], t['topp'], t['rated']
    bounds = [
        ('pair / single items per minute, per seed', f'{num(ratio["mean"])} ± '
         f'{num(ratio["std"], 2)} ({ratio["n"]} seeds)',
         '≥ 1.9 (design documents: 22 / 12 = 1.83)'),
        (f'cycle bound, single arm, bin → pick → bin, {cyc["cases"]} pick points × both bins, '
         'no grasp or release: best', f'{cyc["best_s"]:.2f} s ({cyc["items_per_min_best"]:.1f} '
         f'items/min) at {", ".join(f"{v:.2f}" for v in cyc["best_pick"])} m', ''),
        ('cycle bound: median', f'{cyc["median_s"]:.2f} s ({cyc["items_per_min_median"]:.1f} '
         'items/min)', ''),
        (f'line time / TOPP-RA, {topp["n"]} random lines: best / median / worst',
         f'{topp["min"]:.4f} / {topp["median"]:.4f} / {topp["max"]:.4f}',
         f'≤ 1.01 {met(topp["max"] <= 1.01)}')]
    if rated:
        bounds.append((f'rated feed (an item every {t["rated_feed"]:g} s, collaborative, '
                       f'{rated["sim_seconds"]:.0f} sim s): sorted, missed, dropped + wrong bin, '
                       'give-ups, items/min, min separation',
                       f'{rated["sorted"]}, {rated["missed"]}, '
                       f'{rated["dropped"] + rated["wrong_bin"]}, {rated["give_ups"]}, '
                       f'{num(rated["items_per_minute"])}, {num(rated["min_separation_m"])} m',
                       f'≥ 30/min, none missed {met(_rated_ok(rated))}'))
    out = [table(cap, 'llrrrrrrrrl'),
           table([{'what': w, 'measured': v, 'target': g} for w, v, g in bounds])]
    same = [{'how': what, 'runs': len(runs), 'sorted': _joined(runs, 'sorted'),
             'give-ups': ', '.join(str(result_of(r)[SAME.index('give_ups')]) for r in runs),
             'min separation (m)': ', '.join(repr(r.get('min_separation_m')) for r in runs),
             'result': 'identical' if identical(runs) else 'differ'}
            for what, runs in repeat_sets(t)]
    if same:
        out.append('**Repeatability** (the same seed and flags; "identical": '
                   f'{", ".join(SAME)} all equal):\n\n' + table(same, 'lrrrll'))
    rtf = [{'configuration': f'simulator alone, {r["mode"].replace("_", " ")}, {r["items"]} '
            'items, both arms moving', 'real-time factor': f'{r["rtf"]:.3g}×', 'note': ''}
           for r in t['speed']]
    one = spread(r['real_time_factor'] for r in t['runs'])
    rtf.append({'configuration': 'whole graph in one process, in-process (the capacity runs)',
                'real-time factor': f'{num(one["mean"])}× ({num(one["min"])}–{num(one["max"])})'})
    for name, runs in t['launcher_runs'].items():
        lr, r = launcher(t, name), spread(x.get('real_time_factor') for x in runs)
        rtf.append({'configuration': f'whole graph, the launcher, {name.replace("_", " ")} '
                    '(collaborative, rated feed)', 'real-time factor':
                    f'{num(r["median"])}× ({num(r["min"])}–{num(r["max"])}, {r["n"]} runs)',
                    'note': f'median run: sorted {lr.get("sorted")}, missed {lr.get("missed")}, '
                    f'min separation {num(lr.get("min_separation_m"))} m, exit code '
                    f'{lr.get("exit_code")}'})
    out.append(table(rtf))
    costs = {name: launcher(t, name).get('cpu_per_sim_s') or {} for name in t['launcher_runs']}
    names = sorted({k for c in costs.values() for k in c}, key=lambda k: (k == 'total', k))
    if names:
        out.append("CPU seconds per sim second of each process (the launcher's "
                   '`cpu_per_sim_s`):\n\n' + table(
                       [{'run': run, **{k.replace('_', ' '): num(c.get(k), 2) if k in c else ''
                                        for k in names}} for run, c in costs.items()]))
    return out


def pair_ratio(t: dict) -> dict:
    """Pair / single items per minute, over the seeds run in both modes."""
    single = {r['seed']: r['items_per_minute'] for r in jobs(t, 'single')}
    return spread(r['items_per_minute'] / single[r['seed']] for r in jobs(t, 'collaborative')
                  if single.get(r['seed']))


def _rated_ok(rated: dict) -> bool:
    return rated['items_per_minute'] >= 30.0 and rated['missed'] == 0


def summary(t: dict) -> Rows:
    """Return the summary rows: capacity, rated feed, TOPP-RA, real-time factor, repeats."""
    pair_runs, ratio = jobs(t, 'collaborative'), pair_ratio(t)
    single, pair = (spread(r['items_per_minute'] for r in runs)
                    for runs in (jobs(t, 'single'), pair_runs))
    margin = min((r['min_separation_m'] for r in pair_runs), default=None)
    stops = sum(bool(r['estop']) for r in pair_runs)
    rows = [(f'capacity single / pair (items/min, an item every {t["feed_interval"]:g} s)',
             CLAIMS['throughput'].figure,
             f'{num(single["mean"])} ± {num(single["std"], 2)} / {num(pair["mean"])} ± '
             f'{num(pair["std"], 2)}; pair = {num(ratio["mean"])}× single; min separation '
             f'{num(margin, 3, "m")}, {stops} e-stops', 'pair ≥ 1.9× single, margin kept',
             met(ratio['mean'] >= 1.9 and stops == 0 and margin >= 0.10) if ratio['n'] else '')]
    rated = t['rated']
    if rated:
        rows.append((f'rated feed, collaborative, {rated["sim_seconds"]:.0f} sim s',
                     '22 items/min',
                     f'{num(rated["items_per_minute"])} items/min, {rated["missed"]} missed, '
                     f'{rated["give_ups"]} give-ups', '≥ 30/min, none missed',
                     met(_rated_ok(rated))))
    topp = t['topp']
    rows.append(('line time / TOPP-RA (random lines)', '', f'median {topp["median"]:.4f}, worst '
                 f'{topp["max"]:.4f} ({topp["n"]} lines)', '≤ 1.01', met(topp['max'] <= 1.01)))
    one, sep = launcher(t, 'one_process'), launcher(t, 'processes')
    if one and sep:
        rows.append(('real-time factor, whole graph, unthrottled (launcher)', CLAIMS['rtf'].figure,
                     f'in one process {num(one["real_time_factor"], 2)}× '
                     f'({num(one["cpu_per_sim_s"]["total"], 2)} CPU s per sim s); as separate '
                     f'processes {num(sep["real_time_factor"], 2)}× '
                     f'({num(sep["cpu_per_sim_s"]["total"], 2)} CPU s per sim s)',
                     '≥ 5× one process, ≥ 3.5× processes',
                     met(one['real_time_factor'] >= 5.0 and sep['real_time_factor'] >= 3.5)))
    sets = repeat_sets(t)
    if sets:
        rows.append(('the same seed and flags, the same result', '', '; '.join(
            f'{what.split(" (")[0]}: {"identical" if identical(runs) else "differ"} over '
            f'{len(runs)}' for what, runs in sets), 'identical',
            met(all(identical(runs) for _, runs in sets))))
    return rows


def figure(t: dict):
    """Items per minute per mode and seed, with the design documents' claims."""
    fig, (ax,) = axes(6.0, 3.6)
    for i, mode in enumerate(t['modes']):
        vals = [r['items_per_minute'] for r in jobs(t, mode)]
        ax.bar(i, np.mean(vals), color=f'C{i}', alpha=0.5)
        ax.plot([i] * len(vals), vals, 'ko', ms=4, label='one seed' if i == 0 else None)
        if mode in CLAIMED:
            ax.plot([i - 0.4, i + 0.4], [CLAIMED[mode]] * 2, 'r--',
                    label="design documents' claim" if mode == 'single' else None)
    ax.set_xticks(range(len(t['modes'])), t['modes'])
    finish(ax, '', 'items sorted per sim minute',
           f'capacity: an item every {t["feed_interval"]:g} s, {t["duration"]:g} sim s per run',
           {60.0 / t['feed_interval']: 'item feed'})
    return fig
