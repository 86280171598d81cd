#!/usr/bin/env python3
"""Benchmark the motion core side by side with reference implementations, in one run.

Prints IK (scalar and vectorised, against a plain textbook numpy IK), the Jacobian and
inverse dynamics (against Pinocchio), segment distance (against coal), and the straight-line
move against the time-optimal joint move between the same ends. Figures are medians of
repeated runs on this machine; the CPU is named in the header.

Usage: bench_core.py [--quick] [--json FILE]
"""
import argparse
import json
import platform
import sys
import time
import timeit

import numpy as np

from scara_collab.core import collision, dynamics, kinematics, trajectory
from scara_collab.core.model import expand_xacro, load_cell

SEEDS_MOVE = (np.array([3.2, -0.9, 0.4]), np.array([2.0, 0.0, 0.4]))


def cpu_name() -> str:
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def per_call(fn, number: int, repeat: int = 5) -> float:
    """Return the median seconds per call."""
    return float(np.median(timeit.repeat(fn, number=number, repeat=repeat))) / number


def textbook_ik(l1: float, l2: float, xy: np.ndarray) -> np.ndarray:
    """Solve the seeds' IK, vectorised with numpy, elbow up only, no checks (the reference)."""
    c2 = np.clip((np.sum(xy ** 2, axis=1) - l1 ** 2 - l2 ** 2) / (2 * l1 * l2), -1, 1)
    t2 = np.arccos(c2)
    t1 = np.arctan2(xy[:, 1], xy[:, 0]) - np.arctan2(l2 * np.sin(t2), l1 + l2 * np.cos(t2))
    return np.stack((t1, t2), axis=1)


def progress(msg: str) -> None:
    print(f'  ... {msg}', file=sys.stderr, flush=True)


def run(quick: bool) -> dict:
    import coal
    import pinocchio as pin

    scale = 0.05 if quick else 1.0
    n_vec = int(100_000 * scale) or 1000
    n_call = max(int(20_000 * scale), 200)
    arm = load_cell().leader
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.lower, arm.upper, (n_vec, 3))
    qd = rng.uniform(-2, 2, (n_vec, 3))
    qdd = rng.uniform(-4, 4, (n_vec, 3))
    p = kinematics.fk(arm, q)
    one = (3.5, -1.0, 0.3)
    rows = []

    progress('IK')
    t_ik = per_call(lambda: kinematics.ik(arm, one), n_call)
    t_ikv = per_call(lambda: kinematics.ik(arm, p, q), 1, 5)
    xy = kinematics.world_to_base(arm, p)[:, :2]
    t_ref = per_call(lambda: textbook_ik(arm.l1, arm.l2, xy), 1, 5)
    t_ref1 = per_call(lambda: textbook_ik(arm.l1, arm.l2, xy[:1]), n_call)
    rows += [
        ('IK, one target', f'{t_ik * 1e6:.2f} us', f'{t_ref1 * 1e6:.2f} us (textbook numpy)',
         f'{t_ref1 / t_ik:.1f}x', '<= 5 us', t_ik <= 5e-6),
        (f'IK, {n_vec} targets', f'{n_vec / t_ikv / 1e6:.2f} M/s',
         f'{n_vec / t_ref / 1e6:.2f} M/s (textbook, no checks)', f'{t_ref / t_ikv:.2f}x',
         '>= 1 M/s', n_vec / t_ikv >= 1e6),
    ]

    progress('Jacobian and dynamics vs Pinocchio')
    model = pin.buildModelFromXML(expand_xacro('scara_arm.urdf.xacro', robot=arm.name))
    data = model.createData()
    fid = model.getFrameId(f'{arm.name}_quill')
    q0, qd0, qdd0 = q[0], qd[0], qdd[0]

    def pin_jac():
        pin.computeFrameJacobian(model, data, q0, fid, pin.LOCAL_WORLD_ALIGNED)

    t_j = per_call(lambda: kinematics.jacobian(arm, q0), n_call)
    t_jp = per_call(pin_jac, n_call)
    t_jv = per_call(lambda: kinematics.jacobian(arm, q), 1, 5)
    t_id = per_call(lambda: dynamics.inverse_dynamics(arm, q0, qd0, qdd0, with_friction=False),
                    n_call)
    t_rnea = per_call(lambda: pin.rnea(model, data, q0, qd0, qdd0), n_call)
    t_idv = per_call(lambda: dynamics.inverse_dynamics(arm, q, qd, qdd, with_friction=False),
                     1, 5)
    err = np.max(np.abs(dynamics.inverse_dynamics(arm, q[:200], qd[:200], qdd[:200],
                                                  with_friction=False)
                        - np.array([pin.rnea(model, data, a, b, c)
                                    for a, b, c in zip(q[:200], qd[:200], qdd[:200])])))
    rows += [
        ('Jacobian, one state', f'{t_j * 1e6:.2f} us', f'{t_jp * 1e6:.2f} us (Pinocchio)',
         f'{t_jp / t_j:.2f}x', '', None),
        (f'Jacobian, {n_vec} states', f'{n_vec / t_jv / 1e6:.2f} M/s',
         f'{1 / t_jp / 1e6:.2f} M/s (Pinocchio, one by one)', f'{t_jp * n_vec / t_jv:.1f}x',
         '', None),
        ('inverse dynamics, one state', f'{t_id * 1e6:.2f} us',
         f'{t_rnea * 1e6:.2f} us (Pinocchio rnea)', f'{t_rnea / t_id:.2f}x', '', None),
        (f'inverse dynamics, {n_vec} states', f'{n_vec / t_idv / 1e6:.2f} M/s',
         f'{1 / t_rnea / 1e6:.2f} M/s (rnea one by one)', f'{t_rnea * n_vec / t_idv:.1f}x',
         f'max |diff| {err:.1e} N m', None),
    ]

    progress('segment distance vs coal')
    a0, a1, b0, b1 = (rng.uniform(-1, 1, (n_vec, 3)) for _ in range(4))
    t_sd = per_call(lambda: collision.segment_distance(a0[0], a1[0], b0[0], b1[0]), n_call)
    t_sdv = per_call(lambda: collision.segment_distance(a0, a1, b0, b1), 1, 5)
    caps = coal.Capsule(0.05, 1.0), coal.Capsule(0.05, 1.0)
    tf1, tf2 = coal.Transform3s(), coal.Transform3s()
    tf2.setTranslation(np.array([0.3, 0.2, 0.1]))
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def coal_one():
        res.clear()
        coal.distance(caps[0], tf1, caps[1], tf2, req, res)

    t_coal = per_call(coal_one, n_call)
    t_arm = per_call(lambda: collision.arm_distance(arm, q0, load_cell().follower, q[1]),
                     max(n_call // 10, 50))
    rows += [
        ('segment distance, one pair', f'{t_sd * 1e6:.2f} us',
         f'{t_coal * 1e6:.2f} us (coal capsules, prebuilt)', f'{t_coal / t_sd:.2f}x', '', None),
        (f'segment distance, {n_vec} pairs', f'{n_vec / t_sdv / 1e6:.2f} M/s',
         f'{1 / t_coal / 1e6:.2f} M/s (coal one by one)', f'{t_coal * n_vec / t_sdv:.1f}x',
         '', None),
        ('arm-to-arm distance (9 capsule pairs)', f'{t_arm * 1e6:.1f} us', '', '', '', None),
    ]

    progress('straight line vs joint move (seeds 1.5 m move)')
    p0, p1 = SEEDS_MOVE
    qa = kinematics.ik(arm, p0).unwrap()
    qb = kinematics.ik(arm, p1, qa).unwrap()
    start = time.perf_counter()
    line = trajectory.line_move(arm, qa, p1)
    t_plan = time.perf_counter() - start
    joint = trajectory.joint_move(arm, qa, qb)
    ml, mj = trajectory.path_metrics(line, p0, p1), trajectory.path_metrics(joint, p0, p1)
    rows += [
        ('line move duration (time-optimal)', f'{ml.duration:.3f} s',
         f'{mj.duration:.3f} s (time-optimal joint move)', f'{ml.duration / mj.duration:.2f}x',
         '', None),
        ('line move planning time', f'{t_plan * 1e3:.1f} ms', '', '', '', None),
        ('line deviation (planned)', f'{ml.max_deviation:.1e} m',
         f'{mj.max_deviation:.3f} m (joint interpolation; seeds claim 0.385 m)', '',
         '<= 1e-6 m', ml.max_deviation <= 1e-6),
        ('path length', f'{ml.path_length:.3f} m', f'{mj.path_length:.3f} m (joint)',
         f'{(1 - ml.path_length / mj.path_length) * 100:.1f}% shorter '
         '(seeds claim 14%)', '', None),
    ]
    return {'cpu': cpu_name(), 'python': platform.python_version(), 'quick': quick,
            'rows': [dict(zip(('what', 'ours', 'reference', 'ratio', 'target', 'met'), r))
                     for r in rows]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='few iterations (CI smoke run)')
    parser.add_argument('--json', help='also write the results here')
    args = parser.parse_args(argv)
    res = run(args.quick)
    print(f'motion core benchmark - {res["cpu"]}, Python {res["python"]}'
          + (' (quick run: figures are rough)' if args.quick else ''))
    widths = (38, 14, 46, 12, 12)
    head = ('what', 'ours', 'reference (same run)', 'ratio', 'target')
    print('  '.join(h.ljust(w) for h, w in zip(head, widths)))
    for r in res['rows']:
        target = r['target'] + ('' if r['met'] is None else (' ok' if r['met'] else ' MISSED'))
        print('  '.join(str(v).ljust(w) for v, w in zip(
            (r['what'], r['ours'], r['reference'], r['ratio'], target), widths)))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(res, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
