#!/usr/bin/env python3
"""Run the demo N times while CPU hogs compete and print how many runs completed.

A run *completes* when the launcher exits 0 with a summary whose job sorted items and missed
none. Each run uses its own ROS domain, run folder and the launcher's defaults (the demo's
flags), so the figures are what a user of ``./scripts/demo`` gets on a busy machine::

    .venv/bin/python scripts/bench_robustness.py --runs 5 --hogs 2 --duration 60

The hogs are busy-looping Python processes started before the runs and killed after them
(bounded by the script's own lifetime). Extra launcher flags go after ``--``, e.g.
``-- --fault drop:/automation_manager/start:1``.
"""
import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
HOG = 'import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end: pass\n'


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--runs', type=int, default=5)
    p.add_argument('--hogs', type=int, default=2, help='busy-looping processes (default 2)')
    p.add_argument('--duration', type=float, default=60.0, help='sim seconds per run')
    p.add_argument('--output', type=Path, default=None, help='folder for the run folders')
    p.add_argument('extra', nargs='*', help='more launcher flags (after --)')
    args = p.parse_args()
    out = args.output or Path(tempfile.mkdtemp(prefix='scara_robustness_'))
    out.mkdir(parents=True, exist_ok=True)
    limit = args.runs * (args.duration * 3 + 120)
    hogs = [subprocess.Popen([sys.executable, '-c', HOG.format(limit=limit)])
            for _ in range(args.hogs)]
    rows = []
    try:
        for k in range(args.runs):
            run = out / f'run{k + 1}'
            env = dict(os.environ, ROS_DOMAIN_ID=str(60 + k % 30),
                       ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
            cmd = [sys.executable, str(ROOT / 'scripts' / 'launch_cell.py'), '--mode',
                   'collaborative', '--rtf', '0', '--duration', f'{args.duration:g}',
                   '--output', str(run), '--quiet', '--no-plots', *args.extra]
            t0 = time.monotonic()
            code = subprocess.call(cmd, env=env, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
            wall = time.monotonic() - t0
            try:
                s = json.loads((run / 'summary.json').read_text())
            except (OSError, ValueError):
                s = {}
            ok = code == 0 and (s.get('sorted') or 0) > 0 and s.get('missed') == 0
            job = s.get('job') or {}
            rows.append((k + 1, code, s.get('sorted'), s.get('missed'), s.get('dropped'),
                         job.get('give_ups'), job.get('retries'), s.get('min_separation_m'),
                         s.get('real_time_factor'), wall, ok, s.get('exit_reason')))
            print(f'run {k + 1}: exit {code}, sorted {s.get("sorted")}, missed '
                  f'{s.get("missed")}, dropped {s.get("dropped")}, give-ups '
                  f'{job.get("give_ups")}, retries {job.get("retries")}, wall {wall:.0f} s, '
                  f'{"completed" if ok else "FAILED: " + str(s.get("exit_reason"))}', flush=True)
    finally:
        for h in hogs:
            h.kill()
    done = sum(r[10] for r in rows)
    print(f'\n{done} of {len(rows)} runs completed with {args.hogs} CPU hogs '
          f'({args.duration:g} sim s each; run folders in {out})')
    print('| run | exit | sorted | missed | dropped | give-ups | retries | min sep (m) | RTF |')
    print('|---|---|---|---|---|---|---|---|---|')
    for r in rows:
        sep = 'n/a' if r[7] is None else f'{r[7]:.3f}'
        rtf = 'n/a' if r[8] is None else f'{r[8]:.2f}'
        print(f'| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} | {r[6]} | {sep} | {rtf} |')
    return 0 if done == len(rows) else 1


if __name__ == '__main__':
    sys.exit(main())
