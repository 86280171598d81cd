#!/usr/bin/env python3
"""Measure every result the design documents claim, on this machine; write docs/RESULTS.md.

One command, seven sections (path deviation, solver speed, payload response,
synchronisation, singularity, collision foresight, capacity and real-time factor), each with
the seeds' claimed figure beside the measured one, a progress line per section with the
elapsed time, PNG figures under ``<out>/figures/``. The full run takes about 20 minutes on
2 cores (the capacity runs are most of it); ``--smoke`` is a seconds-long version with tiny
sizes (CI runs it).

Usage: benchmark.py [--smoke] [--out DIR] [--only SECTION ...] [--json FILE] [--no-readme]

By default the results go to ``docs/`` and the summary block of ``README.md`` (between its
``benchmark:summary`` markers) is refreshed; with ``--smoke`` they go to a temporary folder
unless ``--out`` is given, and the README is left alone. Exit status 1 if a section failed.
"""
import argparse
import os
from pathlib import Path
import shlex
import sys
import tempfile

from scara_collab.bench import report, suite
from scara_collab.bench.sections import SECTIONS
from scara_collab.bench.util import Progress

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    """Run the sections and write RESULTS.md, the figures and README's block.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    :return: 1 if a section failed, else 0.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--smoke', action='store_true',
                        help='tiny sizes, one short job: seconds, not minutes (CI)')
    parser.add_argument('--out', type=Path, default=None,
                        help='folder for RESULTS.md and figures/ (default: docs/, or a '
                        'temporary folder with --smoke)')
    keys = [s.key for s in SECTIONS]
    parser.add_argument('--only', nargs='+', choices=keys, default=None, metavar='SECTION',
                        help=f'run only these sections ({", ".join(keys)})')
    parser.add_argument('--json', type=Path, default=None,
                        help='also write every measured value here')
    parser.add_argument('--no-readme', action='store_true',
                        help='do not refresh the summary block of README.md')
    args = parser.parse_args(argv)
    # The in-process graphs must not hear another ROS graph on this machine (a demo, a test):
    # a domain of our own unless the caller chose one, and discovery on this host only.
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = args.out
    if out is None:
        out = Path(tempfile.mkdtemp(prefix='scara_bench_smoke_')) if args.smoke \
            else ROOT / 'docs'
    given = list(sys.argv[1:] if argv is None else argv)
    command = ' '.join(['scripts/benchmark.py'] + ([shlex.join(given)] if given else []))
    progress = Progress()
    progress.note(f'writing {out / "RESULTS.md"} and {out / "figures"}/'
                  + (' (smoke run)' if args.smoke else ''))
    results = suite.run(out, smoke=args.smoke, only=args.only, progress=progress,
                        json_path=args.json, command=command)
    readme = ROOT / 'README.md'
    if not (args.smoke or args.only or args.no_readme) and out.resolve() == (ROOT / 'docs'):
        if report.update_readme(readme, results):
            progress.note(f'refreshed the summary block of {readme}')
    bad = suite.failed(results)
    print(f'{out / "RESULTS.md"} written in {progress.elapsed():.0f} s'
          + (f'; FAILED sections: {", ".join(bad)}' if bad else ''))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
