#!/usr/bin/env python3
"""Run the cell in real time without lockstep beside lockstep's figures; print and write them.

Conditions (:mod:`scara_collab.bench.realtime`): ``lockstep`` (the reference), ``quiet``,
``hog`` (one CPU hog), ``latency`` (20 +- 10 ms on the joint states and statuses),
``two_hogs``; then the capacity at an item every 0.9 s with and without lockstep::

    .venv/bin/python scripts/bench_realtime.py --duration 600 --seeds 1 2 3
    .venv/bin/python scripts/bench_realtime.py --duration 120 --seeds 1 --conditions quiet hog

Each run takes its duration in wall time (``--rtf 1``). The table goes to stdout and to
``--out`` (default ``docs/REALTIME.md``). Exit status 1 if a run broke the margin, missed or
dropped an item, or stopped for the job's own moves (``two_hogs`` may stop, protectively).
"""
import argparse
from pathlib import Path
import shlex
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scara_collab.bench import realtime  # noqa: E402
from scara_collab.bench.util import Progress  # noqa: E402


def _bad(r) -> bool:
    sep = r.get('min_separation_m')
    broken = sep is None or sep < 0.10
    if r['condition'] == 'two_hogs':
        return broken or bool(r.get('emergency'))
    return broken or bool(r.get('missed')) or bool(r.get('dropped')) or bool(r.get('own_moves'))


def main() -> int:
    """Run the conditions and the capacity; print the table and write it.

    :return: 1 if a run failed its target (see the module docstring), else 0.
    """
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=600.0, help='sim seconds per run')
    p.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3])
    p.add_argument('--conditions', nargs='+', default=list(realtime.CONDITIONS),
                   choices=list(realtime.CONDITIONS))
    p.add_argument('--capacity-duration', type=float, default=240.0,
                   help='sim seconds per capacity run (0: no capacity runs)')
    p.add_argument('--out', type=Path, default=ROOT / 'docs' / 'REALTIME.md')
    args = p.parse_args()
    log = Progress().note
    runs = Path(tempfile.mkdtemp(prefix='scara_realtime_'))
    log(f'run folders in {runs}')
    rows = realtime.matrix(runs, args.conditions, args.seeds, args.duration, log=log)
    cap = (realtime.capacity(runs, args.seeds, args.capacity_duration, log=log)
           if args.capacity_duration > 0 else None)
    command = 'scripts/bench_realtime.py ' + shlex.join(sys.argv[1:])
    text = realtime.markdown(rows, cap, command.strip(), args.duration)
    print(text)
    args.out.write_text(text, encoding='utf-8')
    bad = [f'{r["condition"]} seed {r["seed"]}' for r in rows if _bad(r)]
    if cap and cap['ratio'] is not None and cap['ratio'] < 0.95:
        bad.append(f'capacity ratio {cap["ratio"]} < 0.95')
    print(f'written {args.out}' + (f'; not met: {", ".join(bad)}' if bad else '; all met'))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
