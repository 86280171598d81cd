#!/usr/bin/env python3
"""Benchmark the PyBullet cell: simulation speed, and PID vs computed-torque tracking.

1. Physics steps per second and real-time factor of the full cell (both arms moving back and
   forth on 1.5 m lines, control on, unthrottled) with 0, 5 and 10 items on the belt.
2. The same planned 1.5 m straight line (``core.trajectory.line_move``) executed by the seeds'
   PID gains and by computed torque, with 0, 1.0 and 2.5 kg hung on the tool: max tracking
   error (joints and tool), settling time (tool within 1 mm of the goal for good, after the
   trajectory ends), peak effort per joint and overshoot along the line, printed beside the
   figures the seeds claim (never measured there).

The measurements are :mod:`scara_collab.bench.physics` (``scripts/benchmark.py`` runs the same
code). Usage: bench_sim.py [--seconds S] [--repeat N] [--settle S] [--pid-settle S]
[--servo-rate HZ]. Progress goes to stderr, the tables to stdout.
"""
import argparse
import sys

from scara_collab.bench import physics
from scara_collab.bench.claims import PAYLOAD_CLAIMS
from scara_collab.bench.util import stderr_log


def main(argv=None) -> int:
    """Print the simulation speed and the PID vs computed-torque tracking; return 0.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=3.0,
                        help='sim seconds per throughput run (default 3)')
    parser.add_argument('--repeat', type=int, default=3,
                        help='throughput runs per case, the median is shown (default 3)')
    parser.add_argument('--settle', type=float, default=2.0,
                        help='sim seconds observed after the trajectory ends (default 2)')
    parser.add_argument('--pid-settle', type=float, default=10.0,
                        help='the same for PID, which is much slower (default 10)')
    parser.add_argument('--servo-rate', type=float, default=None,
                        help='override simulation.yaml servo_rate for the throughput runs')
    args = parser.parse_args(argv)

    speed = physics.speed_study(seconds=args.seconds, repeat=args.repeat,
                                servo_rate=args.servo_rate, log=stderr_log)
    by_case = {(r['items'], r['mode']): r for r in speed['rows']}
    print(f'\n## Simulation speed (physics {speed["physics_rate"]:.0f} Hz, servo '
          f'{speed["servo_rate"]:.0f} Hz, {speed["solver_iterations"]} solver iterations, '
          'both arms moving, unthrottled, one core, median of '
          f'{args.repeat} runs of {args.seconds:g} s)\n')
    print('| items | computed torque steps/s | RTF | PID steps/s | RTF |')
    print('|---:|---:|---:|---:|---:|')
    for n_items in sorted({r['items'] for r in speed['rows']}):
        ct, pid = by_case[(n_items, 'computed_torque')], by_case[(n_items, 'pid')]
        print(f'| {n_items} | {ct["steps_per_s"]:,.0f} | {ct["rtf"]:.1f}x | '
              f'{pid["steps_per_s"]:,.0f} | {pid["rtf"]:.1f}x |')

    study = physics.payload_study(settle=args.settle, pid_settle=args.pid_settle,
                                  log=stderr_log)
    start, goal = study['line']
    print(f'\n## Tracking: planned 1.5 m line {tuple(start)} -> {tuple(goal)} '
          f'({study["arm"]}, {study["rows"][0]["duration"]:.2f} s), payload on the tool\n')
    print('| payload | controller | max joint error (mrad, mrad, mm) | max tool error mm | '
          'settling to 1 mm | final error mm | peak effort (N m, N m, N) | overshoot | '
          'seeds claim (settle, torque, overshoot) |')
    print('|---:|---|---|---:|---:|---:|---|---:|---|')
    for r in study['rows']:
        claim = PAYLOAD_CLAIMS[r['payload']]
        je = r['joint_err'] * 1e3
        settle = (f'{r["settling"]:.3f} s' if r['settling'] is not None
                  else f'not within {r["window"]:g} s')
        print(f'| {r["payload"]} kg | {r["mode"]} | {je[0]:.2f}, {je[1]:.2f}, {je[2]:.2f} | '
              f'{r["tool_err"] * 1e3:.2f} | {settle} | {r["final"] * 1e3:.3f} | '
              f'{r["peak"][0]:.1f}, {r["peak"][1]:.1f}, {r["peak"][2]:.1f} | '
              f'{r["overshoot"]:.2f} % | {claim[0]} s, {claim[1]} N m, {claim[2]} % |')
    print('\nSettling: time after the trajectory ends until the tool stays within 1 mm of the '
          'goal. Overshoot: furthest tool travel past the goal along the line, % of 1.5 m. '
          "PID uses the seeds' gains (planar 15/0.5/2, quill 10/0.1/1) unchanged.")
    return 0


if __name__ == '__main__':
    sys.exit(main())
