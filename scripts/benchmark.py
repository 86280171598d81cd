#!/usr/bin/env python3
"""Measure every result the design documents claim, on this machine; write docs/RESULTS.md.

Default: the seven numbered sections of ``RESULTS.md``; ``--only`` also runs those through the
launcher (``REALTIME.md``, ``LINE.md``, blocks of ``RESULTS.md``): docs/benchmarks.md. Exit
status 1 if a section failed or missed its targets.
"""
import argparse
import os
from pathlib import Path
import shlex
import sys
import tempfile

from scara_collab.bench import faults, line, protocol, realtime, report, soak
from scara_collab.bench.util import Progress

ROOT = Path(__file__).resolve().parents[1]
LAUNCHER = {'protocol': protocol, 'faults': faults, 'soak': soak, 'realtime': realtime,
            'line': line}
KEYS = [s.key for s in report.SECTIONS] + list(LAUNCHER)


def keys(text: str) -> list:
    """Parse one ``--only`` value: a key or a comma list of keys."""
    out = [k.strip() for k in text.split(',') if k.strip()]
    bad = [k for k in out if k not in KEYS]
    if bad:
        raise argparse.ArgumentTypeError(f'unknown section {bad}; one of {", ".join(KEYS)}')
    return out


def parse(argv=None) -> argparse.Namespace:
    """Return the parsed command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--only', type=keys, action='append', metavar='SECTION',
                   help=f'run only these sections: {", ".join(KEYS)}')
    p.add_argument('--smoke', action='store_true', help='tiny sizes: seconds, not minutes')
    p.add_argument('--out', type=Path, default=None,
                   help='folder for RESULTS.md, REALTIME.md and figures/ (default docs/); '
                   'a .md path is the real-time page')
    p.add_argument('--json', type=Path, default=None,
                   help='also write every measured value of the numbered sections here')
    p.add_argument('--duration', type=float, default=None,
                   help='sim s per run: realtime (600), soak (3600)')
    p.add_argument('--seeds', type=int, nargs='+', default=None,
                   help='seeds: realtime (1 2 3), protocol mirrored runs (11 12 13)')
    p.add_argument('--conditions', nargs='+', default=None, choices=list(realtime.CONDITIONS),
                   help='realtime conditions (default all)')
    p.add_argument('--one-process', action='store_true',
                   help='realtime: every node of the cell in one process, in every run')
    p.add_argument('--capacity-duration', type=float, default=None,
                   help='realtime: sim s per capacity run (240; 0: none)')
    p.add_argument('--warm', type=float, default=None, help='soak: sim s left out (300)')
    p.add_argument('--cases', type=int, nargs='+', default=None,
                   help='faults: case numbers, 1-based (default all)')
    p.add_argument('--runs', type=int, default=None, help='protocol: demo runs with hogs (5)')
    p.add_argument('--hogs', type=int, default=None, help='protocol: CPU hogs (2)')
    p.add_argument('--cells', type=int, nargs='+', default=None,
                   help='line: line lengths (2 3), each beside one cell')
    p.add_argument('--scenarios', nargs='+', default=None,
                   choices=('capacity', 'rated', 'realtime', 'kill'),
                   help='line: capacity (default), rated (N x the rated feed, lossy handoffs), '
                   'realtime (N x the rated feed, unthrottled and at 1x), '
                   'kill (cell 1 of 3 killed at 300 sim s)')
    return p.parse_args(argv)


def main(argv=None) -> int:
    """Run the sections and write their blocks; return 1 if one failed or missed its targets."""
    args = parse(argv)
    only = [k for group in args.only or [] for k in group] or [s.key for s in report.SECTIONS]
    # The in-process graphs must not hear another ROS graph on this machine (a demo, a test):
    # a domain of our own unless the caller chose one, and discovery on this host only.
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = args.out
    if out is None:
        out = Path(tempfile.mkdtemp(prefix='scara_bench_')) if args.smoke else ROOT / 'docs'
    page = out if out.suffix == '.md' else out / 'REALTIME.md'
    out = out.parent if out.suffix == '.md' else out
    out.mkdir(parents=True, exist_ok=True)
    given = sys.argv[1:] if argv is None else list(argv)
    command = shlex.join(['scripts/benchmark.py', *given])
    progress = Progress()
    bad = []
    numbered = [k for k in only if k not in LAUNCHER]
    if numbered:
        progress.note(f'writing {out / "RESULTS.md"} and {out / "figures"}/')
        results = report.run(out, args.smoke, numbered, progress, args.json, command)
        bad += report.failed(results)
    for key in (k for k in only if k in LAUNCHER):
        with progress.section(key):
            target = page if key == 'realtime' else out / 'RESULTS.md'
            if not LAUNCHER[key].section(args, target, command, progress.note):
                bad.append(key)
    print(f'{out} written in {progress.elapsed():.0f} s'
          + (f'; FAILED or targets missed: {", ".join(bad)}' if bad else ''))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
