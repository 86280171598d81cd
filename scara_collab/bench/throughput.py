"""Section 7, throughput and real-time factor: the sorting job's capacity, and what bounds it.

The measurements are :func:`scara_collab.bench.job.run_job` (the whole graph in one process)
over seeds and modes, :func:`scara_collab.bench.job.run_launcher` (one process per node, and
``--one-process``), :func:`scara_collab.bench.capacity.cycle_bound` and
:func:`scara_collab.bench.capacity.topp_ratios`; this module runs them with its sizes and is
their summary rows, Markdown (with the simulator's speed from section 3) and figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.bench import capacity, job
from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.util import (canvas, m, md_table, met, num, plural, Progress, quote, Rows,
                                     save, Section, spread, usable)


TARGETS = {
    'pair_ratio': 1.9,             # pair / single items per minute
    'pair_rate': 30.0,             # items/min
    'margin': 0.10,                # m, arm-to-arm, never broken
    'rtf': 5.0,                    # whole graph, unthrottled, in one process
    'rtf_processes': 3.5,          # whole graph, unthrottled, one process per node (issue 15)
    'topp': 1.01,                  # line time / TOPP-RA, worst case (issue 15)
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""
CLAIMED = {'single': 12.0, 'collaborative': 22.0}
"""The seeds' capacity per mode, items/min (:data:`~scara_collab.bench.claims.CLAIMS`
``'throughput'``)."""
COLOURS = {'single': 'tab:orange', 'collaborative': 'tab:blue', 'mirrored': 'tab:purple'}


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


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Run the capacity runs, the repeats, the rated feed, the launcher, the cycle bound, TOPP."""
    feed = sizes.capacity_feed
    runs: List[dict] = []
    for seed in sizes.job_seeds:
        for mode in sizes.job_modes:
            progress.note(f'capacity: {mode}, seed {seed}, an item every {feed:g} s, '
                          f'{sizes.job_duration:g} sim s')
            runs.append(job.run_job(mode, sizes.job_duration, feed=feed, seed=seed,
                                    log=progress.note, report_every=60.0))
    first = sizes.job_seeds[0]
    repeats = [r for r in runs if r['mode'] == 'collaborative' and r['seed'] == first]
    for k in range(1, sizes.repeats):
        progress.note(f'repeat {k + 1}/{sizes.repeats}: collaborative, seed {first}')
        repeats.append(job.run_job('collaborative', sizes.job_duration, feed=feed, seed=first,
                                   log=progress.note, report_every=60.0))
    rated = None
    if sizes.rated_duration > 0:
        progress.note(f'rated feed: collaborative, an item every {job.default_feed():g} s, '
                      f'{sizes.rated_duration:g} sim s')
        rated = job.run_job('collaborative', sizes.rated_duration, seed=first,
                            log=progress.note, report_every=60.0)
    launchers, launcher_runs = {}, {}
    if sizes.launcher_duration > 0:
        for k in range(sizes.launcher_repeats):  # interleaved: the machine's drift hits both
            for name, flags in (('processes', ()), ('one_process', ('--one-process',))):
                progress.note(f'launcher ({name.replace("_", " ")}, run {k + 1}/'
                              f'{sizes.launcher_repeats}): collaborative, unthrottled, '
                              f'{sizes.launcher_duration:g} sim s')
                launcher_runs.setdefault(name, []).append(job.run_launcher(
                    'collaborative', sizes.launcher_duration,
                    scratch / f'launcher_{name}_{k + 1}', seed=first, extra=flags))
        launchers = {name: median_run(runs) for name, runs in launcher_runs.items()}
    progress.note('cycle bound: bin -> pick -> bin over the belt')
    cycle = capacity.cycle_bound(step=sizes.cycle_step)
    try:
        ratios = capacity.topp_ratios(sizes.topp_lines)
        topp = {'n': len(ratios), 'median': float(np.median(ratios)),
                'worst': float(ratios.max()), 'best': float(ratios.min())}
    except ImportError as exc:
        topp = {'error': f'toppra not installed ({exc})'}
    return {'runs': runs, 'mirrored': None, 'repeats': repeats, 'rated': rated,
            'launchers': launchers, 'launcher_runs': launcher_runs, 'cycle': cycle,
            'topp': topp,
            'duration': sizes.job_duration, 'seeds': list(sizes.job_seeds),
            'modes': list(sizes.job_modes), 'feed_interval': feed,
            'rated_feed': job.default_feed()}


# --- figures derived from the runs, shared by the summary and the text ------------------------
#: what "the same job result" compares, to the last bit
SAME = ('sorted', 'missed', 'dropped', 'wrong_bin', 'give_ups', 'retries', 'min_separation_m',
        'min_separation_time')


def result_of(run: dict) -> tuple:
    """Return what :data:`SAME` compares (the launcher's summary keeps give-ups in ``job``)."""
    job_stats = run.get('job') or {}
    return tuple(run.get(k, job_stats.get(k)) for k in SAME)


def median_run(runs: Sequence[dict]) -> dict:
    """Return the run of median real-time factor (a failed run if there is no other)."""
    good = sorted((r for r in runs if 'error' not in r), key=lambda r: r['real_time_factor'])
    return good[(len(good) - 1) // 2] if good else runs[0]


def identical(runs: Sequence[dict]) -> Optional[bool]:
    """Return True if the runs' job results agree to the last bit (None: fewer than 2)."""
    good = [r for r in runs if 'error' not in r]
    if len(good) < 2 or len(good) < len(runs):
        return None if len(runs) < 2 else False
    return len({result_of(r) for r in good}) == 1


def repeat_sets(t: dict) -> List[Tuple[str, List[dict]]]:
    """Return the repeated runs: in-process, then the launcher's, each with its name."""
    out = [('in one process (in-process job, an item every '
            f'{t["feed_interval"]:g} s, {t["duration"]:g} sim s)', list(t.get('repeats') or []))]
    for name, what in (('one_process', 'through the launcher, --one-process'),
                       ('processes', 'through the launcher, one process per node')):
        runs = (t.get('launcher_runs') or {}).get(name) or []
        if runs:
            out.append((f'{what} (rated feed, {runs[0].get("sim_seconds", 0):.0f} sim s)', runs))
    return [(what, runs) for what, runs in out if len(runs) > 1]


def jobs(data: dict, mode: str) -> List[dict]:
    """Return the capacity runs of ``mode``."""
    return [r for r in data['runs'] if r['mode'] == mode]


def mirrored_run(data: dict) -> Optional[dict]:
    """Return the mirrored job's run (None if there was none)."""
    runs = jobs(data, 'mirrored')
    return runs[0] if runs else data.get('mirrored')


def _launcher(data: dict, name: str) -> Optional[dict]:
    run = (data.get('launchers') or {}).get(name)
    return run if run and 'error' not in run else None


def _cost(run: dict) -> Optional[float]:
    return (run.get('cpu_per_sim_s') or {}).get('total')


def _range(t: dict, name: str) -> str:
    """`` (median of 3, 4.6–5.1×)`` over the launcher's repeats of ``name``."""
    rtf = [r['real_time_factor'] for r in (t.get('launcher_runs') or {}).get(name) or []
           if 'error' not in r]
    if len(rtf) < 2:
        return ''
    return f' (median of {len(rtf)}, {num(min(rtf), 2)}–{num(max(rtf), 2)}×)'


def pair_ratio(data: dict) -> Dict[str, float]:
    """Pair / single items per minute, per seed run with both modes."""
    single = {r['seed']: r['items_per_minute'] for r in jobs(data, 'single')}
    pair = {r['seed']: r['items_per_minute'] for r in jobs(data, 'collaborative')}
    return spread(pair[s] / single[s] for s in single if s in pair and single[s] > 0)


# --- the summary -------------------------------------------------------------------------------
def summary(t: dict) -> Rows:
    """Return the summary rows: capacity, rated feed, TOPP-RA, the launcher's real-time factor."""
    single = spread(r['items_per_minute'] for r in jobs(t, 'single'))
    pair_runs = jobs(t, 'collaborative')
    pair = spread(r['items_per_minute'] for r in pair_runs)
    ratio = pair_ratio(t)
    margin = min((r['min_separation_m'] for r in pair_runs
                  if r.get('min_separation_m') is not None), default=None)
    stops = sum(1 for r in pair_runs if r.get('estop'))
    ok = None
    if pair['n'] and ratio['n']:
        ok = (ratio['mean'] >= TARGETS['pair_ratio'] and stops == 0
              and margin is not None and margin >= TARGETS['margin'])
    rows = [(f'capacity single / pair (items/min, an item every {t["feed_interval"]:g} s)',
             CLAIMS['throughput'].figure,
             f'{num(single["mean"])} ± {num(single["std"], 2)} / {num(pair["mean"])} ± '
             f'{num(pair["std"], 2)}; pair = {num(ratio["mean"])}× single; min '
             f'separation {m(margin)}, {stops} e-stops',
             'pair ≥ 1.9× single, margin kept', met(ok))]
    rated = t.get('rated')
    if rated:
        rows.append((f'rated feed, collaborative, {rated["sim_seconds"]:.0f} sim s',
                     '22 items/min', f'{num(rated["items_per_minute"])} items/min, '
                     f'{rated["missed"]} missed, {rated["give_ups"]} give-ups',
                     '≥ 30/min, none missed',
                     met(rated['items_per_minute'] >= TARGETS['pair_rate']
                         and rated['missed'] == 0)))
    topp = t.get('topp') or {}
    if 'worst' in topp:
        rows.append(('line time / TOPP-RA (random lines)', '',
                     f'median {topp["median"]:.4f}, worst {topp["worst"]:.4f} '
                     f'({topp["n"]} lines)', '≤ 1.01 (issue 15)',
                     met(topp['worst'] <= TARGETS['topp'])))
    one, sep = _launcher(t, 'one_process'), _launcher(t, 'processes')
    if one or sep:
        parts = []
        if one:
            parts.append(f'in one process {num(one["real_time_factor"], 2)}×'
                         f'{_range(t, "one_process")} ({num(_cost(one), 2)} CPU s per sim s)')
        if sep:
            parts.append(f'as separate processes {num(sep["real_time_factor"], 2)}×'
                         f'{_range(t, "processes")} ({num(_cost(sep), 2)} CPU s per sim s)')
        ok = None
        if one and sep:
            ok = (one['real_time_factor'] >= TARGETS['rtf']
                  and sep['real_time_factor'] >= TARGETS['rtf_processes'])
        rows.append(('real-time factor, whole graph, unthrottled (launcher)',
                     CLAIMS['rtf'].figure, '; '.join(parts),
                     '≥ 5× one process, ≥ 3.5× processes', met(ok)))
    sets = repeat_sets(t)
    if sets:
        same = [identical(runs) for _, runs in sets]
        rows.append(('the same seed and flags, the same result', '',
                     '; '.join(f'{what.split(" (")[0]}: '
                               f'{"identical" if ok else "differ"} over {len(runs)}'
                               for (what, runs), ok in zip(sets, same)),
                     'identical (issue 15)', met(all(same))))
    return rows


# --- the text ----------------------------------------------------------------------------------
def markdown(t: dict, results: dict) -> str:
    """Return the section's text: capacity per mode, what bounds it, the real-time factors."""
    single = spread(r['items_per_minute'] for r in jobs(t, 'single'))
    speed = results['payload'].get('speed') if usable(results.get('payload')) else None
    parts = [quote('throughput', 'rtf'), _capacity(t), _ratio(pair_ratio(t)),
             _cycle(t.get('cycle') or {}, single), _repeats(t),
             _rated(t), _topp(t.get('topp') or {}),
             *_real_time(t, speed), *_costs(t.get('launchers') or {})]
    return '\n\n'.join(p for p in parts if p)


def _capacity(t: dict) -> str:
    claims = {mode: f'{v:g} items/min' for mode, v in CLAIMED.items()}
    rows = []
    for mode in t['modes']:
        runs = jobs(t, mode)
        ipm = spread(r['items_per_minute'] for r in runs)
        sep = [r['min_separation_m'] for r in runs if r.get('min_separation_m') is not None]
        rows.append((mode, ', '.join(str(r['seed']) for r in runs),
                     f'{num(ipm["mean"])} ± {num(ipm["std"], 2)} ({num(ipm["min"])}–'
                     f'{num(ipm["max"])})',
                     ', '.join(str(r['sorted']) for r in runs),
                     ', '.join(str(r.get('give_ups', 'n/a')) for r in runs),
                     ', '.join(str(r.get('dropped', 0) + r.get('wrong_bin', 0)) for r in runs),
                     m(min(sep)) if sep and mode != 'single' else 'n/a',
                     str(sum(1 for r in runs if r.get('estop'))),
                     num(float(np.mean([r['real_time_factor'] for r in runs])), 2) + '×',
                     claims.get(mode, '')))
    return '\n\n'.join([
        '**Capacity** is items sorted per minute with the feed faster than the arms can take: '
        f'an item every {t["feed_interval"]:g} s ({60 / t["feed_interval"]:.0f}/min, random '
        'lateral offset; mirrored mode: a mirror pair every '
        f'{2 * t["feed_interval"]:g} s). The whole graph (bridge, planners, replication '
        'manager, collision monitor, automation manager) runs in one process on one executor, '
        "unthrottled on sim time with the bridge's lockstep gate on: "
        f'{plural(len(t["seeds"]), "item-feed seed")} ({", ".join(map(str, t["seeds"]))}) × '
        f'{", ".join(t["modes"])}, {t["duration"]:g} sim s each. Items/min = items sorted per '
        'sim minute of the job. Give-ups: moves the job abandoned (an item that got away, a '
        'grasp that failed); dropped + wrong bin: items that left the belt some other way.',
        md_table(('mode', 'seeds', 'items/min mean ± sd (min–max)', 'sorted', 'give-ups',
                  'dropped + wrong bin', 'min separation', 'e-stops', 'real-time factor',
                  "seeds' claim"), rows, 'llrrrrrrrl')])


def _ratio(ratio: Dict[str, float]) -> str:
    if not ratio['n']:
        return ''
    return (f'Pair / single: **{num(ratio["mean"])}** ± {num(ratio["std"], 2)} over '
            f'{ratio["n"]} seeds (seeds: 22 / 12 = 1.83; target ≥ 1.9 with the margin '
            'kept and no emergency stop).')


def _cycle(cyc: dict, single: Dict[str, float]) -> str:
    if not cyc:
        return ''
    frac = single['mean'] / cyc['items_per_min_median'] if single['n'] else None
    return (
        f"**Cycle bound** (a single arm, the planners' own moves from above a bin down to "
        f'an item on the belt and back, {cyc["cases"]} pick points × both bins, no grasp '
        f'or release time): best {cyc["best_s"]:.2f} s ({cyc["items_per_min_best"]:.1f} '
        f'items/min, at {", ".join(f"{v:.2f}" for v in cyc["best_pick"])} m), median '
        f'{cyc["median_s"]:.2f} s ({cyc["items_per_min_median"]:.1f}/min).'
        + (f' The single arm sorts {num(single["mean"])}/min at capacity: {frac:.0%} of the '
           "median-cycle bound; the rest is the job's per-cycle time (grasp and release "
           'calls, the decision lead, waiting for an item to come into reach).'
           if frac else ''))


def _repeats(t: dict) -> str:
    rows = []
    for what, runs in repeat_sets(t):
        same = identical(runs)
        rows.append((what, str(len(runs)), ', '.join(str(r.get('sorted')) for r in runs),
                     ', '.join(str(result_of(r)[SAME.index('give_ups')]) for r in runs),
                     ', '.join(f'{r["min_separation_m"]!r}' if r.get('min_separation_m')
                               is not None else 'n/a' for r in runs),
                     'identical' if same else 'differ'))
    if not rows:
        return ''
    return '\n\n'.join([
        f'**Repeatability**: the same run (collaborative, seed {t["seeds"][0]}, same flags) '
        'repeated; '
        f'"identical" means {", ".join(SAME)} all equal, the minimum separation to the last '
        "bit. In one process every callback takes its turn in the executor's order (the "
        'bridge steps on the lockstep answer that lets it, the sim-time ticks run from the '
        'clock); as separate processes the order in which messages from different processes '
        'arrive within a lockstep window is up to the machine.',
        md_table(('how', 'runs', 'sorted', 'give-ups', 'min separation (m)', 'result'), rows,
                 'lrrrll')])


def _rated(t: dict) -> str:
    rated = t.get('rated')
    if not rated:
        return ''
    return (
        f'**Rated feed** (an item every {t["rated_feed"]:g} s, collaborative, seed '
        f'{rated["seed"]}, {rated["sim_seconds"]:.0f} sim s, one process): '
        f'{rated["sorted"]} sorted, {rated["missed"]} missed, '
        f'{rated.get("dropped", 0) + rated.get("wrong_bin", 0)} dropped or wrong bin, '
        f'{rated["give_ups"]} give-ups, {num(rated["items_per_minute"])} items/min, min '
        f'separation {m(rated["min_separation_m"])}.')


def _topp(topp: dict) -> str:
    if 'worst' in topp:
        return (f'**Line timing against TOPP-RA** (toppra, same path and limits, '
                f'{topp["n"]} random lines): line time / TOPP-RA median '
                f'{topp["median"]:.4f}, best {topp["best"]:.4f}, worst '
                f'{topp["worst"]:.4f} (target ≤ 1.01: {met(topp["worst"] <= TARGETS["topp"])}).')
    if topp:
        return f'Line timing against TOPP-RA: not measured ({topp.get("error")}).'
    return ''


def _real_time(t: dict, speed: Optional[dict]) -> List[str]:
    """Return the real-time factor's paragraph and table: simulator alone, whole graph."""
    rows = []
    if speed:
        for r in speed['rows']:
            rows.append((f'simulator alone, {r["mode"].replace("_", " ")}, {r["items"]} '
                         'items, both arms moving', f'{r["rtf"]:.3g}×',
                         f'{r["steps_per_s"]:,.0f} steps/s'))
    one = spread(r['real_time_factor'] for r in t['runs'])
    if one['n']:
        rows.append(('whole graph in one process, in-process (the capacity runs above)',
                     f'{num(one["mean"], 3)}× ({num(one["min"], 3)}–{num(one["max"], 3)})', ''))
    launchers = t.get('launchers') or {}
    for name, what in (('one_process', 'the launcher, --one-process'),
                       ('processes', 'the launcher, one process per node')):
        lr = launchers.get(name)
        if not lr:
            continue
        if 'error' in lr:
            rows.append((f'whole graph, {what}', 'failed', lr['error']))
            continue
        rows.append((
            f'whole graph, {what} (collaborative, rated feed, {lr["sim_seconds"]:.0f} sim s)',
            f'{num(lr["real_time_factor"], 3)}×',
            f'{num(_cost(lr), 3)} CPU s per sim s; sorted {lr.get("sorted")}, missed '
            f'{lr.get("missed")}, min separation {m(lr.get("min_separation_m"))}, exit code '
            f'{lr.get("exit_code")}'))
    if not rows:
        return []
    head = ''
    if speed:
        head = (f'Simulator alone: {speed["physics_rate"]:.0f} Hz physics, servo '
                f'{speed["servo_rate"]:.0f} Hz, {speed["solver_iterations"]} solver '
                f'iterations, one core, median of {plural(speed["repeat"], "run")} of '
                f'{speed["seconds"]:g} s. ')
    return [head + 'Real-time factor = sim seconds per wall second (seeds: ≈ 1.0; '
            'target ≥ 5× in one process, ≥ 3.5× as separate processes, issue 15). '
            'On a shared machine these are lower bounds.',
            md_table(('configuration', 'real-time factor', 'note'), rows)]


def _costs(launchers: Dict[str, dict]) -> List[str]:
    """Return the CPU cost per process of the launcher runs: a paragraph and a table."""
    names = sorted({k for lr in launchers.values() for k in (lr.get('cpu_per_sim_s') or {})
                    if k != 'total'}, key=lambda k: (k == 'launcher', k))
    rows = [(name.replace('_', ' '), *_cost_cells(lr, names + ['total']))
            for name, lr in launchers.items() if lr and 'error' not in lr]
    if not rows:
        return []
    return ['CPU seconds per sim second of each process over the job (from '
            "`/proc`, the launcher's `cpu_per_sim_s`); the launcher process "
            'records the run.',
            md_table(['run'] + [n.replace('_', ' ') for n in names] + ['total'],
                     rows, 'l' + 'r' * (len(names) + 1))]


def _cost_cells(run: Optional[dict], names: Sequence[str]) -> List[str]:
    cost = (run or {}).get('cpu_per_sim_s') or {}
    return [num(cost[k], 2) if k in cost else '' for k in names]


# --- the figure --------------------------------------------------------------------------------
def figure(data: dict, path: Path) -> None:
    """Items per minute per mode and seed, with the seeds' claims."""
    fig, ax = canvas(6.0, 3.6)
    modes = list(data['modes'])
    for i, mode in enumerate(modes):
        vals = [r['items_per_minute'] for r in data['runs'] if r['mode'] == mode]
        ax.bar(i, np.mean(vals), color=COLOURS.get(mode, 'tab:gray'), alpha=0.5,
               yerr=np.std(vals, ddof=1) if len(vals) > 1 else None, capsize=4)
        ax.plot([i] * len(vals), vals, 'ko', ms=4)
        if mode in CLAIMED:
            ax.plot([i - 0.4, i + 0.4], [CLAIMED[mode]] * 2, 'r--', lw=1.2)
    ax.plot([], [], 'r--', label="seeds' claim")
    ax.plot([], [], 'ko', ms=4, label='one seed')
    ax.axhline(60.0 / data['feed_interval'], color='0.5', ls=':', lw=1)
    ax.text(len(modes) - 0.6, 60.0 / data['feed_interval'] - 1.8, 'item feed', fontsize=7,
            color='0.4', ha='right')
    ax.set_xticks(range(len(modes)))
    ax.set_xticklabels(modes)
    ax.set_ylabel('items sorted per sim minute')
    ax.set_title(f'capacity: an item every {data["feed_interval"]:g} s, {data["duration"]:g} '
                 'sim s per run', fontsize=10)
    ax.legend(fontsize=7, loc='lower right')
    save(fig, path)


SECTION = Section(
    key='throughput', title='throughput: the sorting job',
    heading='Throughput and real-time factor', measure=measure, markdown=markdown,
    summary=summary, figure=figure, figure_alt='items per minute per mode and seed',
    full=Sizes(),
    smoke=Sizes(job_seeds=(1,), job_modes=('collaborative',), job_duration=8.0, repeats=1,
                rated_duration=0.0, launcher_duration=0.0, cycle_step=0.6, topp_lines=2))
