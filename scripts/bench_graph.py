#!/usr/bin/env python3
"""Benchmark the motion graph on sim time: mirroring and straight lines, executed in physics.

Runs the bridge, both planners and the replication manager in one process (one executor,
unthrottled sim time), sends a 1.5 m move like the seeds' through ``/collab/target``
(straight line, then the same move with joint interpolation), and measures from
``/joint_states``: the follower's mirror error, the start lag between the arms, and the
leader's deviation from the straight line; beside the seeds' claims (4 mm, 15 ms, < 1 mm,
0.385 m).

Usage: bench_graph.py [--json FILE]
"""
import argparse
import json
import sys
import time

from geometry_msgs.msg import PointStamped
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.kinematics import fk, ik
from scara_collab.core.mirror import mirror_point
from scara_collab.core.trajectory import segment_deviation
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.params import ros_args
from scara_collab.nodes.planner import Planner
from scara_collab.nodes.pybullet_bridge import PyBulletBridge
from scara_collab.nodes.replication_manager import ReplicationManager
from scara_collab.nodes.runner import close_graph

# A 1.5 m move towards the belt like the seeds' "rest position to the conveyor centre", but
# ending 0.25 m short of the centre line: mirrored, the seeds' own move would put both tools on
# the same belt point, and the right arm (correctly) waits for the left instead.
MOVE = (np.array([3.4, -1.15, 0.4]), np.array([2.2, -0.25, 0.4]))


def measure(mode: str) -> dict:
    """Measure one mirrored move in ``mode`` ('line' or 'joint') through a fresh graph."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    nodes = [
        PyBulletBridge(context=ctx, cli_args=ros_args(
            'simulation', 'controllers', real_time_factor=0.0, feed_interval=0.0)),
        Planner('scara_left', 'left_planner', context=ctx,
                cli_args=ros_args('controllers', mode=mode)),
        Planner('scara_right', 'right_planner', context=ctx,
                cli_args=ros_args('controllers', mode=mode)),
        ReplicationManager(context=ctx, cli_args=ros_args()),
        Node('bench', context=ctx),
    ]
    bridge, left_pl, right_pl, _, probe = nodes
    for n in nodes:
        ex.add_node(n)
    states, trajs = [], {}
    probe.create_subscription(JointState, '/joint_states', states.append, 100)
    for r in ('scara_left', 'scara_right'):
        probe.create_subscription(JointTrajectory, f'/{r}/joint_trajectory',
                                  lambda m, r=r: trajs.__setitem__(r, m), 10)

    def spin_until(pred, timeout=120.0):
        end = time.monotonic() + timeout
        while not pred() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.005)
        if not pred():
            raise RuntimeError('timed out')

    try:
        cell = bridge.cell
        left, right = cell.leader, cell.follower
        spin_until(lambda: left_pl.q is not None and right_pl.q is not None
                   and left_pl._now() > 0.1)
        # put both arms at the start of the seeds' move (mirrored), through the graph itself
        start, goal = MOVE
        for target in (start, goal):
            trajs.clear()
            pub = probe.create_publisher(PointStamped, '/collab/target', 10)
            spin_until(lambda: pub.get_subscription_count() > 0)
            t_send = bridge.sim.time
            pub.publish(conv.make_point_stamped(target))
            spin_until(lambda: len(trajs) == 2)
            end = max(conv.to_sec(m.header.stamp) + conv.to_sec(m.points[-1].time_from_start)
                      for m in trajs.values())
            spin_until(lambda: bridge.sim.time > end + 0.3)
        stamps = {r: conv.to_sec(m.header.stamp) for r, m in trajs.items()}
        t, pl, pr = [], [], []
        for m in states:
            ts = conv.to_sec(m.header.stamp)
            if ts >= t_send:
                t.append(ts)
                pl.append(fk(left, conv.joint_state_arrays(m, left.joint_names)[0]))
                pr.append(fk(right, conv.joint_state_arrays(m, right.joint_names)[0]))
        t, pl, pr = np.array(t), np.array(pl), np.array(pr)
        err = np.linalg.norm(pr - mirror_point(left, right, pl), axis=1)

        def onset(p):
            return t[np.argmax(np.linalg.norm(p - p[0], axis=1) > 1e-4)]

        lag = abs(onset(pl) - onset(pr))
        return {
            'mode': mode,
            'mirror_error_max_m': float(err.max()),
            'mirror_error_mean_m': float(err.mean()),
            'start_stamp_difference_s': abs(stamps['scara_left'] - stamps['scara_right']),
            'start_lag_measured_s': float(lag),
            'state_period_s': float(np.median(np.diff(t))),
            'leader_line_deviation_m': float(segment_deviation(pl, start, goal).max()),
            'leader_end_error_m': float(np.linalg.norm(pl[-1] - goal)),
            'move_length_m': float(np.linalg.norm(goal - start)),
            'physics_step_s': bridge.dt,
            'reachable': bool(ik(left, start).ok and ik(left, goal).ok),
        }
    finally:
        close_graph(ex, nodes, ctx)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    print('  ... straight line through the graph', file=sys.stderr, flush=True)
    line = measure('line')
    print('  ... joint interpolation through the graph', file=sys.stderr, flush=True)
    joint = measure('joint')
    rows = [
        ('mirror error, max (line move)', f'{line["mirror_error_max_m"] * 1e3:.4f} mm',
         '4 mm (average)', '<= 1 mm'),
        ('start lag: stamp difference', f'{line["start_stamp_difference_s"] * 1e3:.1f} ms',
         '15 ms', '<= 1 physics step (1 ms)'),
        ('start lag: measured onset', f'{line["start_lag_measured_s"] * 1e3:.1f} ms '
         f'(states every {line["state_period_s"] * 1e3:.0f} ms)', '15 ms', ''),
        ('executed line deviation (leader)', f'{line["leader_line_deviation_m"] * 1e3:.3f} mm',
         '< 1 mm (planned)', '<= 1 mm'),
        ('joint interpolation deviation (executed)',
         f'{joint["leader_line_deviation_m"]:.3f} m', '0.385 m', 'reported'),
    ]
    print(f'motion graph benchmark - {line["move_length_m"]:.2f} m move (3.4, -1.15) -> '
          '(2.2, -0.25), z 0.4, mirrored onto the right arm, executed in physics')
    print(f'{"what":42s}{"measured":34s}{"seeds claim":18s}target')
    for r in rows:
        print(f'{r[0]:42s}{r[1]:34s}{r[2]:18s}{r[3]}')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump({'line': line, 'joint': joint}, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
