#!/usr/bin/env python3
"""Measure the sorting job with the whole graph in ONE process (lockstep on sim time).

All six nodes share one executor, so sim time cannot run ahead of the planners and the
automation manager while they compute. This isolates the job's own throughput from the
cross-process latency the launcher's separate processes add (see README, Known limits). The
measurement is :func:`scara_collab.bench.job.run_job` (``scripts/benchmark.py`` runs it over
several seeds).

Usage: bench_job.py [--modes single collaborative mirrored] [--duration 120] [--seed N]
                    [--feed S] [--json FILE]
"""
import argparse
import sys

from scara_collab.bench import job
from scara_collab.bench.util import stderr_log, write_json


def main(argv=None) -> int:
    """Run the job in each mode and print its figures and the pair / single ratio.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    :return: 0.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--modes', nargs='+', default=list(job.MODES), choices=job.MODES)
    parser.add_argument('--duration', type=float, default=120.0, help='sim seconds per mode')
    parser.add_argument('--feed', type=float, default=None,
                        help='s between items (default: simulation.yaml)')
    parser.add_argument('--seed', type=int, default=None,
                        help='item feed seed (default: simulation.yaml item_seed)')
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    feed = args.feed or job.default_feed()
    results = {m: job.run_job(m, args.duration, feed, args.seed,
                              log=lambda msg: stderr_log(f'  ... {msg}'))
               for m in args.modes}
    print(f'sorting job, whole graph in one process, {args.duration:.0f} sim s per mode, '
          f'an item every {feed} s ({60 / feed:.1f}/min)')
    print(f'{"mode":15s}{"sorted":>8s}{"missed":>8s}{"dropped":>8s}{"items/min":>11s}'
          f'{"min sep (m)":>13s}{"mirror err (mm)":>17s}{"wall (s)":>10s}{"RTF":>7s}')
    for m, s in results.items():
        mirror = s['mirror_error_max_m']
        print(f'{m:15s}{s["sorted"]:8d}{s["missed"]:8d}{s["dropped"]:8d}'
              f'{s["items_per_minute"]:11.1f}{s["min_separation_m"] or float("nan"):13.3f}'
              f'{(mirror * 1e3 if mirror is not None else float("nan")):17.3f}'
              f'{s["wall_seconds"]:10.1f}{s["real_time_factor"]:7.1f}')
    if 'single' in results and 'collaborative' in results and results['single']['sorted']:
        ratio = results['collaborative']['items_per_minute'] / \
            results['single']['items_per_minute']
        print(f'pair / single: {ratio:.2f} (target >= 1.9)')
    if args.json:
        write_json(args.json, results)
    return 0


if __name__ == '__main__':
    sys.exit(main())
