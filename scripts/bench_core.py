#!/usr/bin/env python3
"""Benchmark the motion core side by side with reference implementations, in one run.

Prints IK (scalar and vectorised, against a plain textbook numpy IK), the Jacobian and the
dynamics (against Pinocchio), capsule distances (against coal), and the seeds' 1.5 m move as a
straight line against the time-optimal joint move between the same ends. Figures are medians
of repeated runs on this machine; the CPU is named in the header. The measurements are
:mod:`scara_collab.bench.solvers` and :mod:`scara_collab.bench.paths` (``scripts/benchmark.py``
runs the same code).

Usage: bench_core.py [--quick] [--json FILE]
"""
import argparse
import sys

from scara_collab.bench import paths, solvers
from scara_collab.bench.util import machine, stderr_log, write_json
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import path_metrics


def line_vs_joint_rows() -> list:
    """Rows for the seeds' 1.5 m move planned both ways (the bench_core table format)."""
    start, goal = paths.SEEDS_MOVE
    plans = paths.plan(load_cell().leader, start, goal)
    ml = path_metrics(plans['line'], start, goal)
    mj = path_metrics(plans['joint'], start, goal)
    return [
        ('line move duration (time-optimal)', f'{ml.duration:.3f} s',
         f'{mj.duration:.3f} s (time-optimal joint move)', f'{ml.duration / mj.duration:.2f}x',
         '', None, ''),
        ('line move planning time', f'{plans["line_plan_time_s"] * 1e3:.1f} ms', '', '', '',
         None, ''),
        ('line deviation (planned)', f'{ml.max_deviation:.1e} m',
         f'{mj.max_deviation:.3f} m (joint interpolation; seeds claim 0.385 m)', '',
         '<= 1e-6 m', ml.max_deviation <= 1e-6, ''),
        ('path length', f'{ml.path_length:.3f} m', f'{mj.path_length:.3f} m (joint)',
         f'{(1 - ml.path_length / mj.path_length) * 100:.1f}% shorter '
         '(seeds claim 14%)', '', None, ''),
    ]


def run(quick: bool) -> dict:
    """Measure; return ``{'cpu', 'python', 'quick', 'rows': [...]}`` (rows as text)."""
    res = solvers.measure(quick, lambda msg: stderr_log(f'  ... {msg}'))
    rows = []
    for r in res['rows']:
        d = solvers.display(r)
        rows.append((r['what'], d['ours'], d['reference'], d['ratio'], r['target'], r['met'],
                     r['note']))
    stderr_log('  ... straight line vs joint move (seeds 1.5 m move)')
    rows += line_vs_joint_rows()
    info = machine()
    return {'cpu': info['cpu'], 'python': info['python'], 'quick': quick,
            'rows': [dict(zip(('what', 'ours', 'reference', 'ratio', 'target', 'met', 'note'), r))
                     for r in rows]}


def main(argv=None) -> int:
    """Run the benchmark and print its table (and JSON with ``--json``); return 0.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='few iterations (CI smoke run)')
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    res = run(args.quick)
    print(f'motion core benchmark - {res["cpu"]}, Python {res["python"]}'
          + (' (quick run: figures are rough)' if args.quick else ''))
    widths = (40, 14, 46, 12, 12)
    head = ('what', 'ours', 'reference (same run)', 'ratio', 'target / note')
    print('  '.join(h.ljust(w) for h, w in zip(head, widths)))
    for r in res['rows']:
        target = r['target'] + ('' if r['met'] is None else (' ok' if r['met'] else ' MISSED'))
        target = '; '.join(filter(None, (target, r['note'])))
        print('  '.join(str(v).ljust(w) for v, w in zip(
            (r['what'], r['ours'], r['reference'], r['ratio'], target), widths)))
    if args.json:
        write_json(args.json, res)
    return 0


if __name__ == '__main__':
    sys.exit(main())
