#!/usr/bin/env python3
"""Measure every result the design documents claim, on this machine; write docs/results/."""
import argparse
import os
from pathlib import Path
import shlex
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmarks/ lies beside scripts/: measured, never installed

from benchmarks import (fault_matrix, job_protocol, line_scenarios,  # noqa: E402
                        people, realtime_runs, results_page, soak)
from benchmarks.util import (FIGURES, LINE_PAGE, Progress, REALTIME_PAGE,  # noqa: E402
                             RESULTS_PAGE)

LAUNCHER = {'protocol': job_protocol, 'faults': fault_matrix, 'soak': soak,
            'realtime': realtime_runs, 'line': line_scenarios, 'people': people}
KEYS = [s.key for s in results_page.SECTIONS] + list(LAUNCHER)


def keys(text: str) -> list:
    """Parse one ``--only`` value: a key or a comma list of keys."""
    out = [k.strip() for k in text.split(',') if k.strip()]
    bad = [k for k in out if k not in KEYS]
    if bad:
        raise argparse.ArgumentTypeError(f'unknown section {bad}; one of {", ".join(KEYS)}')
    return out


OPTIONS = (  # flag, argparse keywords, help
    ('--smoke', dict(action='store_true'), 'tiny sizes: seconds, not minutes'),
    ('--out', dict(type=Path), f'folder for {RESULTS_PAGE}, {REALTIME_PAGE}, {LINE_PAGE} and '
     f'{FIGURES}/ (default docs/results/); a .md path is the real-time page'),
    ('--json', dict(type=Path), 'also write every measured value of the numbered sections here'),
    ('--duration', dict(type=float), 'sim s per run: realtime (600), soak (3600), people (240)'),
    ('--seeds', dict(type=int, nargs='+'), 'seeds: realtime (1 2 3), protocol mirrored runs '
     '(11 12 13), people (1 2 3 4 5; the first two also in real time)'),
    ('--conditions', dict(nargs='+', choices=list(realtime_runs.CONDITIONS)),
     'realtime conditions (default all)'),
    ('--one-process', dict(action='store_true'),
     'realtime: every node of the cell in one process, in every run'),
    ('--capacity-duration', dict(type=float), 'realtime: sim s per capacity run (240; 0: none)'),
    ('--warm', dict(type=float), 'soak: sim s left out (300)'),
    ('--cases', dict(type=int, nargs='+'), 'faults: case numbers, 1-based (default all)'),
    ('--runs', dict(type=int), 'protocol: demo runs with hogs (5)'),
    ('--hogs', dict(type=int), 'protocol: CPU hogs (2)'),
    ('--cells', dict(type=int, nargs='+'), 'line: line lengths (2 3), each beside one cell'),
    ('--people', dict(nargs='+', choices=people.CHOICES),
     'people: the scenarios (default pass-by inlet middle random; nobody: the scanners and the '
     'monitor alone), each beside the same seed without a person; other than the default, '
     'a block of their own'),
    ('--realtime-seeds', dict(type=int), 'people: how many of the seeds also run in real time '
     '(2; once every lockstep pair has run)'),
    ('--scenarios', dict(nargs='+', choices=('capacity', 'rated', 'realtime', 'kill')),
     'line: capacity (default), rated (N x the rated feed, lossy handoffs), realtime (N x the '
     'rated feed, unthrottled and at 1x), kill (cell 1 of 3 killed at 300 sim s)'))


def parse(argv=None) -> argparse.Namespace:
    """Return the parsed command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--only', type=keys, action='append', metavar='SECTION',
                   help=f'run only these sections: {", ".join(KEYS)}')
    for flag, kwargs, text in OPTIONS:
        p.add_argument(flag, help=text, **kwargs)
    return p.parse_args(argv)


def main(argv=None) -> int:
    """Run the sections and write their blocks; return 1 if one failed or missed its targets."""
    args = parse(argv)
    only = ([k for group in args.only or [] for k in group]
            or [s.key for s in results_page.SECTIONS])
    # The in-process graphs must not hear another ROS graph on this machine (a demo, a test):
    # a domain of our own unless the caller chose one, and discovery on this host only.
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = args.out or (Path(tempfile.mkdtemp(prefix='scara_bench_')) if args.smoke
                       else ROOT / 'docs' / 'results')
    page, out = (out, out.parent) if out.suffix == '.md' else (out / REALTIME_PAGE, out)
    out.mkdir(parents=True, exist_ok=True)
    command = shlex.join(['scripts/benchmark.py', *(sys.argv[1:] if argv is None else argv)])
    progress, bad = Progress(), []
    numbered = [k for k in only if k not in LAUNCHER]
    if numbered:
        progress.note(f'writing {out / RESULTS_PAGE} and {out / FIGURES}/')
        results = results_page.run(out, args.smoke, numbered, progress, args.json, command)
        bad += results_page.failed(results)
    for key in (k for k in only if k in LAUNCHER):
        with progress.section(key):
            target = page if key == 'realtime' else out / RESULTS_PAGE
            if not LAUNCHER[key].section(args, target, command, progress.note):
                bad.append(key)
    print(f'{out} written in {progress.elapsed():.0f} s'
          + (f'; FAILED or targets missed: {", ".join(bad)}' if bad else ''))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
