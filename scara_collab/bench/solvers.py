"""Solver speed: the motion core side by side with reference implementations, in one process.

References, timed in the same run on the same inputs:

- IK: a plain textbook numpy IK (the seeds' cosine law, elbow up, no checks), one target and
  vectorised over N;
- Jacobian, inverse dynamics (RNEA), forward dynamics (ABA): Pinocchio on the arm's URDF;
- segment and arm-to-arm capsule distance: coal (hpp-fcl) capsules.

One call is timed as the median of repeated loops (``timeit``); N at once as the median of
repeated vectorised calls. For the references without a batch API, N is one call per item.
``speedup`` is how many times faster ours is (``< 1`` = slower). Each reference is also
checked to agree with ours on the same inputs, so the comparison is like for like.
"""
from functools import partial
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.bench.util import fmt_rate, fmt_seconds, Log, per_call
from scara_collab.core import collision, dynamics, kinematics
from scara_collab.core.model import ArmModel, expand_xacro, load_cell

IK_TARGET = (3.5, -1.0, 0.3)
"""The single IK target (world frame), reachable by the left arm."""


def textbook_ik(l1: float, l2: float, xy: np.ndarray) -> np.ndarray:
    """Solve the seeds' IK, vectorised with numpy, elbow up only, no checks (the reference).

    :param xy: ``(N, 2)`` targets in the base frame, m.
    :return: ``(N, 2)`` ``(theta1, theta2)``, rad.
    """
    c2 = np.clip((np.sum(xy ** 2, axis=1) - l1 ** 2 - l2 ** 2) / (2 * l1 * l2), -1, 1)
    t2 = np.arccos(c2)
    t1 = np.arctan2(xy[:, 1], xy[:, 0]) - np.arctan2(l2 * np.sin(t2), l1 + l2 * np.cos(t2))
    return np.stack((t1, t2), axis=1)


def _latency(what: str, ours: float, ref: Optional[float], ref_name: str, target: str = '',
             met: Optional[bool] = None, note: str = '') -> Dict[str, object]:
    return {'what': what, 'kind': 'latency', 'ours': ours, 'reference': ref,
            'reference_name': ref_name, 'speedup': None if ref is None else ref / ours,
            'target': target, 'met': met, 'note': note}


def _rate(what: str, ours: float, ref: Optional[float], ref_name: str, target: str = '',
          met: Optional[bool] = None, note: str = '') -> Dict[str, object]:
    return {'what': what, 'kind': 'rate', 'ours': ours, 'reference': ref,
            'reference_name': ref_name, 'speedup': None if ref is None else ours / ref,
            'target': target, 'met': met, 'note': note}


def display(row: Dict[str, object]) -> Dict[str, str]:
    """Return the row's figures as text: ``ours``, ``reference``, ``ratio``."""
    fmt = fmt_seconds if row['kind'] == 'latency' else fmt_rate
    ref = '' if row['reference'] is None else \
        f'{fmt(row["reference"])} ({row["reference_name"]})'
    ratio = '' if row['speedup'] is None else f'{row["speedup"]:.2g}x'
    return {'ours': fmt(row['ours']), 'reference': ref, 'ratio': ratio}


def _time_pair(ours: Callable, reference: Callable, states: Sequence[np.ndarray], number: int,
               repeat: int) -> Tuple[float, float, float]:
    """Time ``ours`` and ``reference`` on the first state, and ``ours`` on all at once.

    :param states: the functions' arguments, each ``(N, ...)``: one state is a row of each.
    :param number: calls per timing loop of the one-state calls.
    :return: seconds per call: ``(ours, one state; reference, one state; ours, N states)``.
    """
    first = [x[0] for x in states]
    return (per_call(lambda: ours(*first), number, repeat),
            per_call(lambda: reference(*first), number, repeat),
            per_call(lambda: ours(*states), 1, repeat))


def _max_diff(ours: Callable, reference: Callable, states: Sequence[np.ndarray]) -> float:
    """Return the largest difference of ``ours`` (N states at once) from ``reference`` (one each).

    :param states: the functions' arguments, each ``(N, ...)``.
    """
    theirs = np.array([reference(*state) for state in zip(*states)])
    return float(np.max(np.abs(ours(*states) - theirs)))


def _coal_capsule_pose(coal, p0: np.ndarray, p1: np.ndarray):
    """Return a coal transform whose local z runs along ``p0``-``p1`` (a capsule's axis)."""
    axis = p1 - p0
    z = axis / np.linalg.norm(axis)
    helper = np.eye(3)[np.argmin(np.abs(z))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    rot = np.stack([x, np.cross(z, x), z], axis=1)
    return coal.Transform3s(rot, (p0 + p1) / 2.0)


class _CoalArms:
    """Both arms as coal capsules; :meth:`distance` is the reference arm-to-arm distance."""

    def __init__(self, coal, left: ArmModel, right: ArmModel):
        self.coal = coal
        self.arms = (left, right)
        self.req, self.res = coal.DistanceRequest(), coal.DistanceResult()

    def poses(self, q_left: np.ndarray, q_right: np.ndarray):
        """Return the six capsules (shape, transform) of the pair of states."""
        out = []
        for arm, q in zip(self.arms, (q_left, q_right)):
            start, end, radii = collision.arm_capsules(arm, q)
            out.append([(self.coal.Capsule(float(r), float(np.linalg.norm(e - s))),
                         _coal_capsule_pose(self.coal, s, e))
                        for s, e, r in zip(start, end, radii)])
        return out

    def distance(self, caps) -> float:
        """Smallest surface distance over the 9 capsule pairs (coal queries only)."""
        best = np.inf
        for ca, ta in caps[0]:
            for cb, tb in caps[1]:
                self.res.clear()
                best = min(best, self.coal.distance(ca, ta, cb, tb, self.req, self.res))
        return best


def measure(quick: bool = False, log: Optional[Log] = None) -> Dict[str, object]:
    """Time the motion core and its references; return ``{'rows': [...], 'sizes': {...}}``.

    :param quick: few iterations (a smoke run; the figures are rough).
    :param log: progress callback.
    """
    import coal
    import pinocchio as pin

    log = log or (lambda msg: None)
    scale = 0.02 if quick else 1.0
    n_vec = max(int(100_000 * scale), 1000)
    n_call = max(int(20_000 * scale), 200)
    n_pair = max(n_vec // 20, 200)
    repeat = 3 if quick else 5
    cell = load_cell()
    arm, right = cell.leader, cell.follower
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.lower, arm.upper, (n_vec, 3))
    qd = rng.uniform(-2, 2, (n_vec, 3))
    qdd = rng.uniform(-4, 4, (n_vec, 3))
    p = kinematics.fk(arm, q)
    rows: List[Dict[str, object]] = []

    log('IK vs a textbook numpy IK')
    t_ik = per_call(lambda: kinematics.ik(arm, IK_TARGET), n_call, repeat)
    t_ikv = per_call(lambda: kinematics.ik(arm, p, q), 1, repeat)
    xy = kinematics.world_to_base(arm, p)[:, :2]
    t_ref = per_call(lambda: textbook_ik(arm.l1, arm.l2, xy), 1, repeat)
    t_ref1 = per_call(lambda: textbook_ik(arm.l1, arm.l2, xy[:1]), n_call, repeat)
    sol = kinematics.ik(arm, p, q)
    ok = sol.ok
    ik_err = float(np.max(np.linalg.norm(kinematics.fk(arm, sol.q[ok]) - p[ok], axis=1)))
    rows += [
        _latency('IK, one target', t_ik, t_ref1, 'textbook numpy', '<= 5 us', t_ik <= 5e-6),
        _rate(f'IK, {n_vec} targets', n_vec / t_ikv, n_vec / t_ref,
              'textbook numpy, no checks', '>= 1 M/s', n_vec / t_ikv >= 1e6,
              f'with the reach, limit and elbow checks ({ok.mean():.0%} of the random '
              f'targets inside the reach window); FK round trip {ik_err:.1e} m'),
    ]

    log('Jacobian and dynamics vs Pinocchio')
    model = pin.buildModelFromXML(expand_xacro('scara_arm.urdf.xacro', robot=arm.name))
    data = model.createData()
    fid = model.getFrameId(f'{arm.name}_quill')

    def pin_jac(x):
        return pin.computeFrameJacobian(model, data, x, fid, pin.LOCAL_WORLD_ALIGNED)

    jac = partial(kinematics.jacobian, arm)
    ours_id = partial(dynamics.inverse_dynamics, arm, with_friction=False)
    ours_fd = partial(dynamics.forward_dynamics, arm, with_friction=False)
    rnea, aba = partial(pin.rnea, model, data), partial(pin.aba, model, data)
    tau = ours_id(q, qd, qdd)
    k = min(200, n_vec)
    t_j, t_jp, t_jv = _time_pair(jac, pin_jac, (q,), n_call, repeat)
    jac_err = _max_diff(jac, lambda x: pin_jac(x)[:3], (q[:k],))
    t_id, t_rnea, t_idv = _time_pair(ours_id, rnea, (q, qd, qdd), n_call, repeat)
    id_err = _max_diff(ours_id, rnea, (q[:k], qd[:k], qdd[:k]))
    t_fd, t_aba, t_fdv = _time_pair(ours_fd, aba, (q, qd, tau), n_call, repeat)
    fd_err = _max_diff(ours_fd, aba, (q[:k], qd[:k], tau[:k]))
    rows += [
        _latency('Jacobian, one state', t_j, t_jp, 'Pinocchio'),
        _rate(f'Jacobian, {n_vec} states', n_vec / t_jv, 1 / t_jp, 'Pinocchio, one by one',
              note=f'max diff {jac_err:.1e}'),
        _latency('inverse dynamics, one state', t_id, t_rnea, 'Pinocchio RNEA'),
        _rate(f'inverse dynamics, {n_vec} states', n_vec / t_idv, 1 / t_rnea,
              'RNEA one by one', note=f'max diff {id_err:.1e} N m'),
        _latency('forward dynamics, one state', t_fd, t_aba, 'Pinocchio ABA'),
        _rate(f'forward dynamics, {n_vec} states', n_vec / t_fdv, 1 / t_aba,
              'ABA one by one', note=f'max diff {fd_err:.1e} (rad/s^2, m/s^2)'),
    ]

    log('capsule distance vs coal')
    a0, a1, b0, b1 = (rng.uniform(-1, 1, (n_vec, 3)) for _ in range(4))
    t_sd = per_call(lambda: collision.segment_distance(a0[0], a1[0], b0[0], b1[0]), n_call,
                    repeat)
    t_sdv = per_call(lambda: collision.segment_distance(a0, a1, b0, b1), 1, repeat)
    radius = 0.01
    caps = coal.Capsule(radius, float(np.linalg.norm(a1[0] - a0[0]))), \
        coal.Capsule(radius, float(np.linalg.norm(b1[0] - b0[0])))
    tf1, tf2 = _coal_capsule_pose(coal, a0[0], a1[0]), _coal_capsule_pose(coal, b0[0], b1[0])
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def coal_one():
        res.clear()
        return coal.distance(caps[0], tf1, caps[1], tf2, req, res)

    t_coal = per_call(coal_one, n_call, repeat)
    seg_err = abs(coal_one() + 2 * radius
                  - float(collision.segment_distance(a0[0], a1[0], b0[0], b1[0])[0]))

    coal_arms = _CoalArms(coal, arm, right)
    qr = rng.uniform(right.lower, right.upper, (n_pair, 3))
    ql = q[:n_pair]
    poses = [coal_arms.poses(a, b) for a, b in zip(ql, qr)]
    t_arm = per_call(lambda: collision.arm_distance(arm, ql[0], right, qr[0]),
                     max(n_call // 10, 50), repeat)
    t_arm_coal = per_call(lambda: coal_arms.distance(poses[0]), max(n_call // 10, 50), repeat)
    t_armv = per_call(lambda: collision.arm_distance(arm, ql, right, qr), 1, repeat)
    ours_d = collision.arm_distance(arm, ql, right, qr)
    ref_d = np.array([coal_arms.distance(c) for c in poses])
    apart = ours_d > 1e-3  # coal reports penetration depth differently: compare apart pairs
    arm_err = float(np.max(np.abs(ours_d[apart] - ref_d[apart]))) if apart.any() else 0.0
    rows += [
        _latency('segment distance, one pair', t_sd, t_coal, 'coal capsules, prebuilt',
                 note=f'diff {seg_err:.1e} m'),
        _rate(f'segment distance, {n_vec} pairs', n_vec / t_sdv, 1 / t_coal,
              'coal one by one'),
        _latency('arm-to-arm distance (9 capsule pairs)', t_arm, t_arm_coal,
                 'coal, 9 queries, poses given'),
        _rate(f'arm-to-arm distance, {n_pair} state pairs', n_pair / t_armv,
              1 / t_arm_coal, 'coal one by one', note=f'max diff {arm_err:.1e} m'),
    ]
    return {'rows': rows, 'sizes': {'n_vectorised': n_vec, 'n_calls': n_call,
                                    'n_state_pairs': n_pair, 'repeats': repeat},
            'quick': quick}
