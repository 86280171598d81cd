#!/usr/bin/env python3
"""Benchmark the PyBullet cell: simulation speed, and PID vs computed-torque tracking.

1. Physics steps per second and real-time factor of the full cell (both arms moving back and
   forth on 1.5 m lines, control on, unthrottled) with 0, 5 and 10 items on the belt.
2. The same planned 1.5 m straight line (``core.trajectory.line_move``) executed by the seeds'
   PID gains and by computed torque, with 0, 1.0 and 2.5 kg hung on the tool: max tracking
   error (joints and tool), settling time (tool within 1 mm of the goal for good, after the
   trajectory ends), peak effort per joint and overshoot along the line, printed beside the
   figures the seeds claim (never measured there).

Usage: bench_sim.py [--seconds S] [--repeat N] [--settle S] [--pid-settle S] [--servo-rate HZ]
Progress goes to stderr, the tables to stdout.
"""
import argparse
import sys
import time

import numpy as np

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import line_move
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.reference import HermiteReference

# the seeds' "results" table: payload kg -> (settling s, peak torque N m, overshoot %)
SEED_CLAIMS = {0.0: (0.45, 12.5, 0.2), 1.0: (0.72, 34.2, 1.5), 2.5: (1.15, 88.7, 4.8)}
# a 1.5 m line along x for each arm, clear of the belt (|y| > 0.5) and tool 0.5 m up
LINES = {'scara_left': ((3.3, -0.8, 0.5), (1.8, -0.8, 0.5)),
         'scara_right': ((3.3, 0.8, 0.5), (1.8, 0.8, 0.5))}
PAYLOAD_SIZE = 0.05  # m: a small dense cube, so a sagging quill does not put it on the floor


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _sim_cfg(servo_rate=None) -> dict:
    cfg = dict(load_config('simulation'), feed_interval=0.0)
    if servo_rate:
        cfg['servo_rate'] = float(servo_rate)
    return cfg


def throughput(cell, mode: str, n_items: int, seconds: float, servo_rate=None):
    """Measure steps per second with both arms shuttling and ``n_items`` on the belt.

    Each leg is a two-point cubic from the measured position to the other end of the arm's
    line (joint space, 75 % of the velocity limit), so it is valid whatever the tracking.
    """
    with CellSim(cell, _sim_cfg(servo_rate), control_mode=mode) as sim:
        ends = {}
        for arm in cell.arms:
            ends[arm.name] = [ik(arm, np.array(p)).q for p in LINES[arm.name]]
            sim.reset_arm(arm.name, ends[arm.name][0])
        belt = cell.belt
        for k in range(n_items):
            sim.spawn_item(x=belt.x_start + 0.1 + 0.4 * k)
        steps = int(round(seconds / sim.dt))
        leg = {name: 1 for name in ends}
        start = time.perf_counter()
        done = 0
        while done < steps:
            for arm in cell.arms:
                if not sim.active(arm.name):
                    q_now = sim.arm_state(arm.name)[0]
                    goal = ends[arm.name][leg[arm.name] % 2]
                    span = 1.5 * np.max(np.abs(goal - q_now) / (0.75 * arm.max_velocity))
                    sim.execute(arm.name, sim.time + np.array([0.0, max(span, 0.1)]),
                                [q_now, goal])
                    leg[arm.name] += 1
            sim.step(10)
            done += 10
        wall = time.perf_counter() - start
        alive = len(sim.items())
    return done / wall, done * sim.dt / wall, alive


def tracking(cell, mode: str, payload: float, settle: float):
    """Run the left line with ``payload`` kg on the tool; return the metrics dict."""
    arm = cell.leader
    start, goal = (np.array(p) for p in LINES[arm.name])
    with CellSim(cell, _sim_cfg(), control_mode=mode) as sim:
        q0 = ik(arm, start).q
        sim.reset_arm(arm.name, q0)
        if payload > 0:
            sim.attach_payload(arm.name, payload, size=PAYLOAD_SIZE)
        traj = line_move(arm, q0, goal)
        t0 = sim.time
        sim.execute(arm.name, t0 + traj.t, traj.q, traj.qd, traj.qdd)
        ref = HermiteReference(t0 + traj.t, traj.q, traj.qd, traj.qdd)
        n = int(round((traj.duration + settle) / sim.dt))
        times, qs, efforts = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
        for k in range(n):
            state = sim.joint_state()   # the state the servo sees at this tick
            times[k], qs[k], efforts[k] = sim.time, state.position[:3], state.effort[:3]
            sim.step(1)
        efforts = np.vstack([efforts[1:], sim.joint_state().effort[:3]])  # torque of tick k
    q_ref = np.array([ref.sample(t)[0] for t in times])
    tips, tips_ref = fk(arm, qs), fk(arm, q_ref)
    joint_err = np.abs(qs - q_ref).max(axis=0)
    tool_err = np.linalg.norm(tips - tips_ref, axis=1).max()
    to_goal = np.linalg.norm(tips - goal, axis=1)
    t_end = t0 + traj.duration
    outside = np.nonzero(to_goal > 1e-3)[0]
    if len(outside) == 0:
        settling = 0.0
    elif outside[-1] == n - 1:
        settling = None  # not within 1 mm at the end of the window
    else:
        settling = max(0.0, times[outside[-1] + 1] - t_end)
    length = np.linalg.norm(goal - start)
    along = (tips - goal) @ ((goal - start) / length)
    return {
        'duration': traj.duration,
        'joint_err': joint_err,
        'tool_err': tool_err,
        'settling': settling,
        'final': to_goal[-1],
        'peak': np.abs(efforts).max(axis=0),
        'overshoot': max(0.0, along.max()) / length * 100.0,
    }


def main(argv=None) -> int:
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
    cell = load_cell()
    sim_cfg = _sim_cfg(args.servo_rate)

    rows = []
    for n_items in (0, 5, 10):
        row = [n_items]
        for mode in ('computed_torque', 'pid'):
            _progress(f'throughput: {mode}, {n_items} items ({args.repeat} runs) ...')
            runs = sorted(throughput(cell, mode, n_items, args.seconds, args.servo_rate)
                          for _ in range(args.repeat))
            row += list(runs[len(runs) // 2][:2])  # the median run
        rows.append(row)
    print(f'\n## Simulation speed (physics {sim_cfg["physics_rate"]:.0f} Hz, servo '
          f'{sim_cfg["servo_rate"]:.0f} Hz, {sim_cfg["solver_iterations"]} solver iterations, '
          'both arms moving, unthrottled, one core, median of '
          f'{args.repeat} runs of {args.seconds:g} s)\n')
    print('| items | computed torque steps/s | RTF | PID steps/s | RTF |')
    print('|---:|---:|---:|---:|---:|')
    for n_items, ct_sps, ct_rtf, pid_sps, pid_rtf in rows:
        print(f'| {n_items} | {ct_sps:,.0f} | {ct_rtf:.1f}x | {pid_sps:,.0f} | {pid_rtf:.1f}x |')

    results = {}
    for payload in (0.0, 1.0, 2.5):
        for mode in ('pid', 'computed_torque'):
            _progress(f'tracking: {mode}, payload {payload} kg ...')
            window = args.pid_settle if mode == 'pid' else args.settle
            results[(payload, mode)] = tracking(cell, mode, payload, window)
    print(f'\n## Tracking: planned 1.5 m line {LINES["scara_left"][0]} -> '
          f'{LINES["scara_left"][1]} (scara_left, '
          f'{results[(0.0, "pid")]["duration"]:.2f} s), payload on the tool\n')
    print('| payload | controller | max joint error (mrad, mrad, mm) | max tool error mm | '
          'settling to 1 mm | final error mm | peak effort (N m, N m, N) | overshoot | '
          'seeds claim (settle, torque, overshoot) |')
    print('|---:|---|---|---:|---:|---:|---|---:|---|')
    for payload in (0.0, 1.0, 2.5):
        claim = SEED_CLAIMS[payload]
        for mode in ('pid', 'computed_torque'):
            r = results[(payload, mode)]
            je = r['joint_err'] * [1e3, 1e3, 1e3]
            window = args.pid_settle if mode == 'pid' else args.settle
            settle = (f'{r["settling"]:.3f} s' if r['settling'] is not None
                      else f'not within {window:g} s')
            print(f'| {payload} kg | {mode} | {je[0]:.2f}, {je[1]:.2f}, {je[2]:.2f} | '
                  f'{r["tool_err"] * 1e3:.2f} | {settle} | {r["final"] * 1e3:.3f} | '
                  f'{r["peak"][0]:.1f}, {r["peak"][1]:.1f}, {r["peak"][2]:.1f} | '
                  f'{r["overshoot"]:.2f} % | '
                  f'{claim[0]} s, {claim[1]} N m, {claim[2]} % |')
    print('\nSettling: time after the trajectory ends until the tool stays within 1 mm of the '
          'goal. Overshoot: furthest tool travel past the goal along the line, % of 1.5 m. '
          "PID uses the seeds' gains (planar 15/0.5/2, quill 10/0.1/1) unchanged.")
    return 0


if __name__ == '__main__':
    sys.exit(main())
