"""The job protocol through the launcher: a long run, mirrored seeds, the demo beside CPU hogs."""
from pathlib import Path
import tempfile
import time

from benchmarks.launched import cells, launch, publish, stamp
from benchmarks.util import Log


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the long, mirrored and hogged runs into ``job-protocol``; True if each demo finished."""
    smoke = args.smoke
    long_s, mirrored_s, hog_s = (60.0, 30.0, 30.0) if smoke else (600.0, 90.0, 60.0)
    seeds = (args.seeds or [11, 12, 13])[:1 if smoke else None]
    runs, hogs = args.runs or (2 if smoke else 5), args.hogs or 2
    out = Path(tempfile.mkdtemp(prefix='scara_job_protocol_'))
    t0 = time.monotonic()
    long = launch('collaborative', 0, 'collaborative', long_s, out / 'long', log)
    mirrored = [dict(launch(f'mirrored seed {seed}', 1 + k, 'mirrored', mirrored_s,
                            out / f'mirrored_{seed}', log, seed=seed), seed=seed)
                for k, seed in enumerate(seeds)]
    demo = [dict(launch(f'run {k} with {hogs} hogs', 9 + k, 'collaborative', hog_s,
                        out / f'hogs_{k}', log, hogs=hogs, timeout=hog_s * 6 + 300), run=k)
            for k in range(1, runs + 1)]
    done = [r['exit_code'] == 0 and (r['sorted'] or 0) > 0 and r['missed'] == 0 for r in demo]
    text = '\n\n'.join([
        stamp(command, t0),
        f'**Collaborative, default feed, {long_s:g} sim s through the launcher**',
        cells([long], ('sorted', 'missed', 'dropped', 'wrong_bin', 'give_ups', 'retries',
                       'items_per_minute', 'min_separation_m', 'emergency', 'real_time_factor'))
        + (f'\n\nLast give-up: {long["last_give_up"]}' if long['last_give_up'] else ''),
        f'**Mirrored, {mirrored_s:g} sim s per seed** (in-step error: the replication '
        "manager's, over pairs the bridge started at the same instant from mirrored poses)",
        cells(mirrored, ('seed', 'sorted', 'missed', 'dropped', 'mirror_error_max_m',
                         'mirror_in_step_moves', 'mirror_not_in_step', 'give_ups',
                         'real_time_factor')),
        f'**The demo ({hog_s:g} sim s) with {hogs} CPU hogs: {sum(done)} of {len(demo)} runs '
        'completed** (exit 0, items sorted, none missed)',
        cells(demo, ('run', 'exit_code', 'sorted', 'missed', 'dropped', 'give_ups', 'retries',
                     'min_separation_m', 'real_time_factor'))])
    publish(text, None if smoke else page, 'job-protocol',
            'The job protocol through the launcher', log, out)
    return all(done)
