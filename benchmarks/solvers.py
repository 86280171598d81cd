"""Section 2, solver speed: the motion core against reference implementations, same run."""
from functools import partial
import math
from pathlib import Path
import timeit
from typing import Callable, List, Sequence

import numpy as np

from benchmarks.claims import CLAIMS
from benchmarks.util import axes, finish, fmt_seconds, met, per_call, Rows, table
from scara_collab.core import collision, dynamics, kinematics
from scara_collab.core.model import expand_xacro, load_cell

IK_TARGET = (3.5, -1.0, 0.3)
"""The single IK target (world frame), reachable by the left arm."""


def textbook_ik(l1: float, l2: float, xy: np.ndarray) -> np.ndarray:
    """Solve the design documents' IK for ``(N, 2)`` base-frame targets, elbow up, unchecked."""
    c2 = np.clip((np.sum(xy ** 2, axis=1) - l1 ** 2 - l2 ** 2) / (2 * l1 * l2), -1, 1)
    t2 = np.arccos(c2)
    t1 = np.arctan2(xy[:, 1], xy[:, 0]) - np.arctan2(l2 * np.sin(t2), l1 + l2 * np.cos(t2))
    return np.stack((t1, t2), axis=1)


def branchy_segment(p0, p1, q0, q1) -> float:
    """Return one pair's segment distance: the core's formula with ``if`` for ``where``."""
    (p0x, p0y, p0z), (p1x, p1y, p1z), (q0x, q0y, q0z), (q1x, q1y, q1z) = p0, p1, q0, q1
    d1x, d1y, d1z = p1x - p0x, p1y - p0y, p1z - p0z
    d2x, d2y, d2z = q1x - q0x, q1y - q0y, q1z - q0z
    rx, ry, rz = p0x - q0x, p0y - q0y, p0z - q0z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    b = d1x * d2x + d1y * d2y + d1z * d2z
    c = d1x * rx + d1y * ry + d1z * rz
    f = d2x * rx + d2y * ry + d2z * rz
    nx, ny, nz = d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x
    denom = nx * nx + ny * ny + nz * nz
    if a <= collision._DEGENERATE_SQ:
        s = 0.0
    elif e <= collision._DEGENERATE_SQ:
        s = min(max(-c / a, 0.0), 1.0)
    elif denom <= collision._PARALLEL_SIN_SQ * a * e:
        s = 0.0
    else:  # (-r x d2) . n / |n|^2
        mx, my, mz = d2y * rz - d2z * ry, d2z * rx - d2x * rz, d2x * ry - d2y * rx
        s = min(max((mx * nx + my * ny + mz * nz) / denom, 0.0), 1.0)
    t_free = 0.0 if e <= collision._DEGENERATE_SQ else (b * s + f) / e
    t = min(max(t_free, 0.0), 1.0)
    if a > collision._DEGENERATE_SQ and t != t_free:
        s = min(max((b * t - c) / a, 0.0), 1.0)
    gx, gy, gz = rx + s * d1x - t * d2x, ry + s * d1y - t * d2y, rz + s * d1z - t * d2z
    return math.sqrt(gx * gx + gy * gy + gz * gz)


def branchy_pair_distances(arm_a, q_a, arm_b, q_b) -> np.ndarray:
    """Return the (3, 3) capsule distances of one state pair by :func:`branchy_segment`."""
    caps = [(collision._capsules(collision._ScalarOps, arm, *np.asarray(q).tolist()),
             collision._radii(arm)) for arm, q in ((arm_a, q_a), (arm_b, q_b))]
    return np.array([[branchy_segment(*cap_a, *cap_b) - ra - rb
                      for cap_b, rb in zip(*caps[1])] for cap_a, ra in zip(*caps[0])])


def _row(what: str, kind: str, ours: float, ref: float, ref_name: str, **more) -> dict:
    """Return a timing row: ``kind`` 'latency' (s per call) or 'rate' (per s)."""
    speedup = ref / ours if kind == 'latency' else ours / ref
    return dict({'what': what, 'kind': kind, 'ours': ours, 'reference': ref,
                 'reference_name': ref_name, 'speedup': speedup, 'target': '', 'met': None,
                 'note': ''}, **more)


def _pair_rows(name: str, ours: Callable, ref: Callable, ref_name: str, states: Sequence,
               timed: Callable, unit: str = '') -> List[dict]:
    """Time ``ours`` and ``ref`` on one state, ``ours`` on all at once (``ref`` one by one)."""
    first = [x[0] for x in states]
    one, theirs = (timed(lambda fn=fn: fn(*first)) for fn in (ours, ref))
    n = len(states[0])
    many = timed(lambda: ours(*states), 1)
    k = min(200, n)
    ref_k = np.array([ref(*state) for state in zip(*(x[:k] for x in states))])
    diff = float(np.max(np.abs(ours(*(x[:k] for x in states)) - ref_k)))
    return [_row(f'{name}, one state', 'latency', one, theirs, ref_name),
            _row(f'{name}, {n} states', 'rate', n / many, 1 / theirs, f'{ref_name}, one by one',
                 note=f'max diff {diff:.1e}{unit}')]


def coal_capsules(coal, start: np.ndarray, end: np.ndarray, radii) -> list:
    """Return coal capsules and transforms whose local z runs along each ``start``-``end``."""
    out = []
    for p0, p1, r in zip(start, end, radii):
        z = (p1 - p0) / np.linalg.norm(p1 - p0)
        x = np.cross(np.eye(3)[np.argmin(np.abs(z))], z)
        x /= np.linalg.norm(x)
        out.append((coal.Capsule(float(r), float(np.linalg.norm(p1 - p0))),
                    coal.Transform3s(np.stack([x, np.cross(z, x), z], axis=1), (p0 + p1) / 2)))
    return out


def coal_distance(coal, query, caps_a: list, caps_b: list) -> float:
    """Smallest surface distance over every pair of coal capsules (``query``: made once)."""
    best = math.inf
    for ca, ta in caps_a:
        for cb, tb in caps_b:
            query[1].clear()
            best = min(best, coal.distance(ca, ta, cb, tb, *query))
    return best


def measure(smoke: bool, scratch: Path) -> dict:
    """Time the motion core and its references; return ``{'rows': [...]}``."""
    import coal
    import pinocchio as pin

    scale = 0.02 if smoke else 1.0
    n_vec, n_call = max(int(100_000 * scale), 1000), max(int(20_000 * scale), 200)
    n_pair, repeat = max(n_vec // 20, 200), 3 if smoke else 5
    cell = load_cell()
    arm, right = cell.leader, cell.follower
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.lower, arm.upper, (n_vec, 3))
    qd, qdd = rng.uniform(-2, 2, (n_vec, 3)), rng.uniform(-4, 4, (n_vec, 3))
    p = kinematics.fk(arm, q)

    def timed(fn: Callable, number: int = n_call) -> float:
        return per_call(fn, number, repeat)

    t_ik = timed(lambda: kinematics.ik(arm, IK_TARGET))
    t_ikv = timed(lambda: kinematics.ik(arm, p, q), 1)
    xy = kinematics.world_to_base(arm, p)[:, :2]
    t_ref = timed(lambda: textbook_ik(arm.l1, arm.l2, xy), 1)
    t_ref1 = timed(lambda: textbook_ik(arm.l1, arm.l2, xy[:1]))
    sol = kinematics.ik(arm, p, q)
    ik_err = float(np.max(np.linalg.norm(kinematics.fk(arm, sol.q[sol.ok]) - p[sol.ok], axis=1)))
    rows = [_row('IK, one target', 'latency', t_ik, t_ref1, 'textbook numpy', target='<= 5 us',
                 met=t_ik <= 5e-6),
            _row(f'IK, {n_vec} targets', 'rate', n_vec / t_ikv, n_vec / t_ref,
                 'textbook numpy, no checks', target='>= 1 M/s', met=n_vec / t_ikv >= 1e6,
                 note=f'with the reach, limit and elbow checks ({sol.ok.mean():.0%} of the '
                 f'random targets inside the reach window); FK round trip {ik_err:.1e} m')]

    model = pin.buildModelFromXML(expand_xacro('scara_arm.urdf.xacro', robot=arm.name))
    data = model.createData()
    fid = model.getFrameId(f'{arm.name}_quill')
    ours_id = partial(dynamics.inverse_dynamics, arm, with_friction=False)
    ours_fd = partial(dynamics.forward_dynamics, arm, with_friction=False)
    rows += _pair_rows('Jacobian', partial(kinematics.jacobian, arm),
                       lambda x: pin.computeFrameJacobian(model, data, x, fid,
                                                          pin.LOCAL_WORLD_ALIGNED)[:3],
                       'Pinocchio', (q,), timed)
    rows += _pair_rows('inverse dynamics', ours_id, partial(pin.rnea, model, data),
                       'Pinocchio RNEA', (q, qd, qdd), timed, ' N m')
    rows += _pair_rows('forward dynamics', ours_fd, partial(pin.aba, model, data),
                       'Pinocchio ABA', (q, qd, ours_id(q, qd, qdd)), timed, ' (rad/s^2, m/s^2)')

    query = coal.DistanceRequest(), coal.DistanceResult()
    a0, a1, b0, b1 = (rng.uniform(-1, 1, (n_vec, 3)) for _ in range(4))
    t_sd = timed(lambda: collision.segment_distance(a0[0], a1[0], b0[0], b1[0]))
    t_sdv = timed(lambda: collision.segment_distance(a0, a1, b0, b1), 1)
    caps = [coal_capsules(coal, s[:1], e[:1], [0.01]) for s, e in ((a0, a1), (b0, b1))]
    t_coal = timed(lambda: coal_distance(coal, query, *caps))
    seg_err = abs(coal_distance(coal, query, *caps) + 0.02
                  - float(collision.segment_distance(a0[0], a1[0], b0[0], b1[0])[0]))
    qr, ql = rng.uniform(right.lower, right.upper, (n_pair, 3)), q[:n_pair]
    poses = [[coal_capsules(coal, *collision.arm_capsules(a, x))
              for a, x in ((arm, u), (right, v))] for u, v in zip(ql, qr)]
    n_arm = max(n_call // 10, 50)
    t_arm = timed(lambda: collision.arm_distance(arm, ql[0], right, qr[0]), n_arm)
    t_arm_coal = timed(lambda: coal_distance(coal, query, *poses[0]), n_arm)
    t_armv = timed(lambda: collision.arm_distance(arm, ql, right, qr), 1)
    ours_d = collision.arm_distance(arm, ql, right, qr)
    apart = ours_d > 1e-3  # coal reports penetration depth differently: compare apart pairs
    ref_d = np.array([coal_distance(coal, query, *c) for c in poses])
    arm_err = float(np.max(np.abs(ours_d - ref_d)[apart], initial=0.0))
    rows += [
        _row('segment distance, one pair', 'latency', t_sd, t_coal, 'coal capsules, prebuilt',
             note=f'diff {seg_err:.1e} m'),
        _row(f'segment distance, {n_vec} pairs', 'rate', n_vec / t_sdv, 1 / t_coal,
             'coal one by one'),
        _row('arm-to-arm distance (9 capsule pairs)', 'latency', t_arm, t_arm_coal,
             'coal, 9 queries, poses given'),
        _row(f'arm-to-arm distance, {n_pair} state pairs', 'rate', n_pair / t_armv,
             1 / t_arm_coal, 'coal one by one', note=f'max diff {arm_err:.1e} m')]

    one = partial(collision.arm_pair_distances, arm, ql[0], right, qr[0])
    branchy = partial(branchy_pair_distances, arm, ql[0], right, qr[0])
    best, number = [math.inf, math.inf], max(n_call // 20, 50)
    for _ in range(5 * repeat):  # interleaved, the minimum: robust to a shared machine
        for k, fn in enumerate((one, branchy)):
            best[k] = min(best[k], timeit.timeit(fn, number=number))
    same = max(float(np.max(np.abs(branchy_pair_distances(arm, u, right, v)
                                   - collision.arm_pair_distances(arm, u, right, v))))
               for u, v in zip(ql, qr))
    rows.append(_row('capsule distances, one state pair (the one formula)', 'latency',
                     best[0] / number, best[1] / number, 'branchy plain-float formula',
                     note=f'max diff over {n_pair} pairs {same:.1e} m'))
    return {'rows': rows}


def _fmt(row: dict, value: float) -> str:
    if row['kind'] == 'latency':
        return fmt_seconds(value)
    for unit, scale in (('M/s', 1e6), ('k/s', 1e3)):
        if value >= scale:
            return f'{value / scale:.3g} {unit}'
    return f'{value:.3g} /s'


def tables(s: dict) -> list:
    """Return every timing beside its reference."""
    return [table([{
        'what': r['what'], 'ours': _fmt(r, r['ours']),
        'reference (same run)': f'{_fmt(r, r["reference"])} ({r["reference_name"]})',
        'ours vs reference': f'{r["speedup"]:.2g}x', 'agreement / note': r['note'],
        'SPEC target': f'{r["target"]} {met(r["met"])}'.strip(),
        "design documents' claim":
            CLAIMS['ik_latency'].figure if r['what'] == 'IK, one target' else ''}
        for r in s['rows']])]


def summary(s: dict) -> Rows:
    """Return the summary row: IK latency, one target and vectorised."""
    one, vec = s['rows'][:2]
    return [('IK latency', CLAIMS['ik_latency'].figure,
             f'{fmt_seconds(one["ours"])} one target; {vec["ours"] / 1e6:.3g} M targets/s '
             'vectorised', '≤ 5 µs; ≥ 10⁶/s', met(one['met'] and vec['met']))]


def figure(s: dict):
    """Speed-up of the motion core over each reference, log scale."""
    rows = s['rows']
    fig, (ax,) = axes(8.0, 0.32 * len(rows) + 1.2)
    y = np.arange(len(rows))[::-1]
    vals = np.array([r['speedup'] for r in rows])
    ax.barh(y, vals, color=['tab:green' if v >= 1 else 'tab:red' for v in vals], alpha=0.7)
    ax.set_xscale('log')
    ax.axvline(1.0, color='k', lw=0.8)
    ax.set_yticks(y, [f'{r["what"]} (vs {r["reference_name"]})' for r in rows], fontsize=7)
    for yi, v in zip(y, vals):
        ax.text(v, yi, f' {v:.2g}x', va='center', fontsize=7)
    finish(ax, 'how many times faster ours is (log; < 1 = slower)', '',
           'motion core vs references, same run')
    return fig
