#!/usr/bin/env python3
"""Run the demo N times while CPU hogs compete and print how many runs completed.

A run *completes* when the launcher exits 0 with a summary whose job sorted items and missed
none. Each run has its own ROS domain and run folder::

    .venv/bin/python scripts/bench_robustness.py --runs 5 --hogs 2 --duration 60

Extra launcher flags go after ``--``, e.g. ``-- --fault drop:/automation_manager/start:1``.
``scripts/bench_job_protocol.py`` runs this too and writes the table into the docs.
"""
import argparse
from pathlib import Path
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scara_collab.bench.protocol import robustness  # noqa: E402
from scara_collab.bench.util import Progress  # noqa: E402


def main() -> int:
    """Run the demo with CPU hogs and print how many runs completed.

    :return: 0 if every run completed, else 1.
    """
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--runs', type=int, default=5)
    p.add_argument('--hogs', type=int, default=2, help='busy-looping processes (default 2)')
    p.add_argument('--duration', type=float, default=60.0, help='sim seconds per run')
    p.add_argument('--output', type=Path, default=None, help='folder for the run folders')
    p.add_argument('extra', nargs='*', help='more launcher flags (after --)')
    args = p.parse_args()
    out = args.output or Path(tempfile.mkdtemp(prefix='scara_robustness_'))
    rows = robustness(out, args.runs, args.hogs, args.duration, args.extra,
                      log=Progress().note)
    done = sum(r['completed'] for r in rows)
    print(f'{done} of {len(rows)} runs completed with {args.hogs} CPU hogs '
          f'({args.duration:g} sim s each; run folders in {out})')
    return 0 if done == len(rows) else 1


if __name__ == '__main__':
    sys.exit(main())
