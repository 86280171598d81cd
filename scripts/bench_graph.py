#!/usr/bin/env python3
"""Benchmark the motion graph on sim time: mirroring and straight lines, executed in physics.

Runs the bridge, both planners and the replication manager in one process (one executor,
unthrottled sim time), sends a 1.5 m move like the seeds' through ``/collab/target``
(straight line, then the same move with joint interpolation), and measures from
``/joint_states``: the follower's mirror error, the start lag between the arms, and the
leader's deviation from the straight line; beside the seeds' claims (4 mm, 15 ms, < 1 mm,
0.385 m). The measurement is :func:`scara_collab.bench.graph.measure` (``scripts/benchmark.py``
runs it on more moves).

Usage: bench_graph.py [--moves N] [--json FILE]
"""
import argparse
import sys

from scara_collab.bench import graph
from scara_collab.bench.util import stderr_log, write_json


def main(argv=None) -> int:
    """Measure the moves through the graph and print them beside the claims; return 0.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--moves', type=int, default=1,
                        help='mirrored moves to measure: the 1.5 m move, then random lines')
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    targets = graph.mirrored_targets(args.moves)
    stderr_log('  ... straight lines through the graph')
    line = graph.measure('line', targets, log=stderr_log)
    stderr_log('  ... joint interpolation through the graph')
    joint = graph.measure('joint', targets[:2], log=stderr_log)

    def ms(x):
        return 'n/a' if x is None else f'{x * 1e3:.1f} ms'

    rows = [
        ('mirror error, max (line moves)', f'{line["mirror_error_max_m"] * 1e3:.4f} mm',
         '4 mm (average)', '<= 1 mm'),
        ('start lag: stamp difference', ms(line['start_stamp_difference_s']), '15 ms',
         '<= 1 physics step (1 ms)'),
        ('start lag: bridge start difference', ms(line['bridge_start_difference_s']), '15 ms',
         '<= 1 physics step (1 ms)'),
        ('start lag: measured onset', f'{ms(line["start_lag_measured_s"])} '
         f'(states every {line["state_period_s"] * 1e3:.0f} ms)', '15 ms', ''),
        ('executed line deviation (leader)', f'{line["leader_line_deviation_m"] * 1e3:.3f} mm',
         '< 1 mm (planned)', '<= 1 mm'),
        ('joint interpolation deviation (executed)',
         f'{joint["leader_line_deviation_m"]:.3f} m', '0.385 m', 'reported'),
    ]
    start, goal = (tuple(p.tolist()) for p in graph.MOVE)
    print(f'motion graph benchmark - {len(line["moves"])} mirrored move(s), the first '
          f'{start} -> {goal} (1.5 m), mirrored onto the right arm, executed in '
          'physics')
    print(f'{"what":42s}{"measured":34s}{"seeds claim":18s}target')
    for r in rows:
        print(f'{r[0]:42s}{r[1]:34s}{r[2]:18s}{r[3]}')
    if args.json:
        write_json(args.json, {'line': line, 'joint': joint})
    return 0


if __name__ == '__main__':
    sys.exit(main())
