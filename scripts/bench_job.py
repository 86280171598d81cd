#!/usr/bin/env python3
"""Measure the sorting job with the whole graph in ONE process (lockstep on sim time).

All six nodes share one executor, so sim time cannot run ahead of the planners and the
automation manager while they compute. This isolates the job's own throughput from the
cross-process latency the launcher's separate processes add (see README, Known limits).

Usage: bench_job.py [--modes single collaborative mirrored] [--duration 120] [--json FILE]
"""
import argparse
import json
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from scara_collab.core.config import load_config
from scara_collab.nodes.automation_manager import AutomationManager
from scara_collab.nodes.collision_monitor import CollisionMonitor
from scara_collab.nodes.params import ros_args
from scara_collab.nodes.planner import Planner
from scara_collab.nodes.pybullet_bridge import PyBulletBridge
from scara_collab.nodes.replication_manager import ReplicationManager
from scara_collab.nodes.runner import close_graph


def run(mode: str, duration: float, feed: float) -> dict:
    """Run one mode for ``duration`` sim seconds; return the job's stats and the wall time."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    pattern = 'mirror_pairs' if mode == 'mirrored' else 'random'
    bridge = PyBulletBridge(context=ctx, cli_args=ros_args(
        'simulation', 'controllers', real_time_factor=0.0, feed_interval=feed,
        feed_pattern=pattern))
    nodes = [bridge,
             Planner('scara_left', 'left_planner', context=ctx, cli_args=ros_args('controllers')),
             Planner('scara_right', 'right_planner', context=ctx,
                     cli_args=ros_args('controllers')),
             ReplicationManager(context=ctx, cli_args=ros_args()),
             CollisionMonitor(context=ctx, cli_args=ros_args())]
    job = AutomationManager(context=ctx, cli_args=ros_args('automation', mode=mode,
                                                           auto_start='true'))
    nodes.append(job)
    for n in nodes:
        ex.add_node(n)
    wall = time.monotonic()
    next_report = 10.0
    try:
        while bridge.sim.time < duration:
            ex.spin_once(timeout_sec=0.01)
            if bridge.sim.time >= next_report:
                s = job.stats()
                print(f'  ... {mode}: {bridge.sim.time:.0f}/{duration:.0f} s, sorted '
                      f'{s["sorted"]}, missed {s["missed"]}', file=sys.stderr, flush=True)
                next_report += 10.0
        out = job.stats()
        out['wall_seconds'] = round(time.monotonic() - wall, 1)
        out['feed_interval'] = feed
        return out
    finally:
        close_graph(ex, nodes, ctx)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--modes', nargs='+', default=['single', 'collaborative', 'mirrored'])
    parser.add_argument('--duration', type=float, default=120.0, help='sim seconds per mode')
    parser.add_argument('--feed', type=float, default=None,
                        help='s between items (default: simulation.yaml)')
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    feed = args.feed or float(load_config('simulation')['feed_interval'])
    results = {m: run(m, args.duration, feed) for m in args.modes}
    print(f'sorting job, whole graph in one process, {args.duration:.0f} sim s per mode, '
          f'an item every {feed} s ({60 / feed:.1f}/min)')
    print(f'{"mode":15s}{"sorted":>8s}{"missed":>8s}{"dropped":>8s}{"items/min":>11s}'
          f'{"min sep (m)":>13s}{"mirror err (mm)":>17s}{"wall (s)":>10s}')
    for m, s in results.items():
        mirror = s['mirror_error_max_m']
        print(f'{m:15s}{s["sorted"]:8d}{s["missed"]:8d}{s["dropped"]:8d}'
              f'{s["items_per_minute"]:11.1f}{s["min_separation_m"] or float("nan"):13.3f}'
              f'{(mirror * 1e3 if mirror is not None else float("nan")):17.3f}'
              f'{s["wall_seconds"]:10.1f}')
    if 'single' in results and 'collaborative' in results and results['single']['sorted']:
        ratio = results['collaborative']['items_per_minute'] / \
            results['single']['items_per_minute']
        print(f'pair / single: {ratio:.2f} (target >= 1.9)')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
