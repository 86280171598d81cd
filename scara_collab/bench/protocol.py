"""The job protocol under load, through the launcher (separate processes).

A long collaborative run, mirrored runs over several seeds (the replication manager's in-step
mirror error), and the demo repeated while CPU hogs compete; each run in its own ROS domain,
its figures from its ``summary.json``.
"""
from pathlib import Path
import tempfile
import time

from scara_collab.bench.launched import cells, launch, stamp
from scara_collab.bench.report import write_block
from scara_collab.bench.util import Log


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the three measurements; print the tables, write them as the ``job-protocol`` block.

    Sizes: 600 sim s collaborative, mirrored seeds 11 12 13 (``args.seeds``) 90 sim s each,
    ``args.runs`` (5) demo runs of 60 sim s beside ``args.hogs`` (2) CPU hogs; with
    ``args.smoke`` 60 s, one seed of 30 s, 2 runs of 30 s (printed, not written).

    :return: True if every demo run beside the hogs completed.
    """
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
        stamp(command, t0, 'each row is one launcher run (separate processes, unthrottled, '
              'lockstep on), its figures from its `summary.json`.'),
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
    print(text)
    if not smoke:
        write_block(page, 'job-protocol', 'The job protocol through the launcher', text)
    log(f'run folders in {out}')
    return all(done)
