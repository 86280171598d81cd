"""The whole benchmark: every section in one run, with progress, figures and ``RESULTS.md``.

:func:`run` measures the sections of :data:`SECTIONS` (sizes from a :class:`Sizes`: the full
run or the seconds-long smoke run), draws the figures (:mod:`scara_collab.bench.figures`) and
writes the report (:mod:`scara_collab.bench.report`). A section that fails is reported as
failed (with the error) and the others still run.
"""
from dataclasses import asdict, dataclass
import json
from pathlib import Path
import resource
import tempfile
import time
import traceback
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.bench import (
    capacity, figures, foresight, graph, job, paths, physics, report, singularity, solvers)
from scara_collab.bench.util import machine, Progress


@dataclass(frozen=True)
class Sizes:
    """How much each section runs (the full run's defaults take about 20 minutes on 2 cores)."""

    quick_solvers: bool = False
    payloads: Tuple[float, ...] = (0.0, 1.0, 2.5)
    settle: float = 2.0              # s observed after the move, computed torque
    pid_settle: float = 10.0         # s observed after the move, PID
    speed_items: Tuple[int, ...] = (0, 5, 10)
    speed_modes: Tuple[str, ...] = ('computed_torque', 'pid')
    speed_seconds: float = 3.0
    speed_repeat: int = 3
    mirrored_moves: int = 6
    singularity_dt: float = 0.001
    foresight_pairs: int = 200
    foresight_execute: int = 30
    job_seeds: Tuple[int, ...] = (1, 2, 3)
    job_modes: Tuple[str, ...] = ('single', 'collaborative', 'mirrored')
    job_duration: float = 240.0      # sim s per capacity run (shorter runs read low)
    capacity_feed: float = 1.0       # s per item: faster than the arms can take (~60/min)
    repeats: int = 3                 # collaborative, first seed: the same run this many times
    rated_duration: float = 600.0    # sim s of collaborative at the rated feed; 0 = none
    launcher_duration: float = 60.0  # sim s of each launcher run (processes, one process)
    cycle_step: float = 0.1          # m between pick points of the cycle bound
    topp_lines: int = 100            # random lines timed against TOPP-RA


FULL = Sizes()
SMOKE = Sizes(quick_solvers=True, settle=0.2, pid_settle=0.5, speed_items=(0,),
              speed_modes=('computed_torque',), speed_seconds=0.5, speed_repeat=1,
              mirrored_moves=1, singularity_dt=0.01, foresight_pairs=6, foresight_execute=2,
              job_seeds=(1,), job_modes=('collaborative',), job_duration=8.0, repeats=1,
              rated_duration=0.0, launcher_duration=0.0, cycle_step=0.6, topp_lines=2)


def _paths(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    return paths.measure()


def _solvers(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    return solvers.measure(sizes.quick_solvers, progress.note)


def _payload(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    out = physics.payload_study(payloads=sizes.payloads, settle=sizes.settle,
                                pid_settle=sizes.pid_settle, log=progress.note)
    out['speed'] = physics.speed_study(items=sizes.speed_items, modes=sizes.speed_modes,
                                       seconds=sizes.speed_seconds, repeat=sizes.speed_repeat,
                                       log=progress.note)
    return out


def _sync(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    targets = graph.mirrored_targets(sizes.mirrored_moves)
    return graph.measure('line', targets, log=progress.note)


def _singularity(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    return singularity.measure(sizes.singularity_dt, progress.note)


def _foresight(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    return foresight.measure(sizes.foresight_pairs, sizes.foresight_execute, log=progress.note)


def _throughput(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
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
    launchers = {}
    if sizes.launcher_duration > 0:
        for name, flags in (('processes', ()), ('one_process', ('--one-process',))):
            progress.note(f'launcher ({name.replace("_", " ")}): collaborative, unthrottled, '
                          f'{sizes.launcher_duration:g} sim s')
            launchers[name] = job.run_launcher('collaborative', sizes.launcher_duration,
                                               scratch / f'launcher_{name}', seed=first,
                                               extra=flags)
    progress.note('cycle bound: bin -> pick -> bin over the belt')
    cycle = capacity.cycle_bound(step=sizes.cycle_step)
    try:
        ratios = capacity.topp_ratios(sizes.topp_lines)
        topp = {'n': len(ratios), 'median': float(np.median(ratios)),
                'worst': float(ratios.max()), 'best': float(ratios.min())}
    except ImportError as exc:
        topp = {'error': f'toppra not installed ({exc})'}
    return {'runs': runs, 'mirrored': None, 'repeats': repeats, 'rated': rated,
            'launchers': launchers, 'cycle': cycle, 'topp': topp,
            'duration': sizes.job_duration, 'seeds': list(sizes.job_seeds),
            'modes': list(sizes.job_modes), 'feed_interval': feed,
            'rated_feed': job.default_feed()}


Section = Callable[[Sizes, Progress, Path], dict]
SECTIONS: Dict[str, Tuple[str, Section]] = {
    'paths': ('path deviation: straight line vs joint interpolation', _paths),
    'solvers': ('solver speed vs reference implementations', _solvers),
    'payload': ('payload response and simulator speed', _payload),
    'sync': ('synchronisation: mirrored moves through the graph', _sync),
    'singularity': ('singularity: pseudo-inverse vs DLS', _singularity),
    'foresight': ('collision foresight on crossing moves', _foresight),
    'throughput': ('throughput: the sorting job', _throughput),
}
"""Section key -> (title, function), in report order."""


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and its finished children so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def jsonable(x):
    """Convert numpy values (recursively) to plain Python for ``json``."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def run(out: Path, sizes: Sizes = FULL, only: Optional[Sequence[str]] = None,
        progress: Optional[Progress] = None, smoke: bool = False,
        json_path: Optional[Path] = None, command: str = '') -> Dict[str, object]:
    """Measure the sections, write ``out/RESULTS.md`` and ``out/figures/*.png``.

    :param only: section keys to run (default all); the others are reported as not run.
    :param command: the command line, quoted in the report.
    :return: ``{'meta': ..., <section key>: data or {'error': ...}}``.
    """
    progress = progress or Progress()
    out = Path(out)
    (out / 'figures').mkdir(parents=True, exist_ok=True)
    results: Dict[str, object] = {
        'meta': {**machine(), 'smoke': smoke, 'sizes': asdict(sizes), 'command': command,
                 'date': time.strftime('%Y-%m-%d %H:%M %Z'), 'sections_s': {}}}
    with tempfile.TemporaryDirectory(prefix='scara_bench_') as scratch:
        for key, (title, fn) in SECTIONS.items():
            if only and key not in only:
                results[key] = {'skipped': True}
                continue
            try:
                with progress.section(title):
                    results[key] = fn(sizes, progress, Path(scratch))
            except Exception as exc:  # noqa: B902 - one broken section must not hide the rest
                results[key] = {'error': f'{type(exc).__name__}: {exc}',
                                'traceback': traceback.format_exc()}
            results['meta']['sections_s'][key] = progress.sections.get(title)
    with progress.section('figures and report'):
        results['figures'] = figures.draw_all(results, out / 'figures')
        results['meta']['wall_s'] = progress.elapsed()
        results['meta']['cpu_s'] = cpu_seconds()
        target = out / 'RESULTS.md'
        # the launcher's tables come from their own scripts (KEPT_BLOCKS): keep them
        old = target.read_text() if target.is_file() else ''
        kept = ''.join(f'\n## {title}\n\n{block}\n' for name, title in KEPT_BLOCKS
                       for block in [report.kept_block(old, name)] if block)
        target.write_text(report.render(results) + kept)
    if json_path:
        Path(json_path).write_text(json.dumps(jsonable(results), indent=1))
    return results


#: generated blocks of RESULTS.md written by other scripts, with their section titles:
#: scripts/bench_job_protocol.py, scripts/bench_faults.py, scripts/bench_soak.py
KEPT_BLOCKS = (('job-protocol', 'The job protocol through the launcher'),
               ('faults', 'Faults against the launcher'),
               ('soak', 'Soak: an hour of sim time through the launcher'))


def failed(results: Dict[str, object]) -> List[str]:
    """Return the keys of the sections that failed."""
    return [k for k in SECTIONS if isinstance(results.get(k), dict) and 'error' in results[k]]
