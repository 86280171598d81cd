"""Section 2, solver speed: the motion core against reference implementations, same run.

The measurement is :func:`scara_collab.bench.solvers.measure` (IK against a textbook numpy IK,
Jacobian and dynamics against Pinocchio, capsule distances against coal); this module is its
summary row, its Markdown and its figure.
"""
from dataclasses import dataclass
from functools import partial
import math
from pathlib import Path
import timeit
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.util import (canvas, fmt_rate, fmt_seconds, Log, md_table, met, num,
                                     per_call, Progress, quote, Rows, save, Section)
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


def min_interleaved(fns: Sequence[Callable], number: int, repeat: int) -> List[float]:
    """Return the smallest seconds per call of each of ``fns``, their loops interleaved.

    Interleaving and the minimum make the ratio of two fast calls robust to a shared machine.
    """
    best = [math.inf] * len(fns)
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            best[k] = min(best[k], timeit.timeit(fn, number=number) / number)
    return best


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


def _branchy_segment(p0, p1, q0, q1) -> float:
    """Return the segment distance of one pair of float 3-tuples, with branches.

    :func:`scara_collab.core.collision.segment_distance` written for one pair only: ``if``
    instead of ``where``; the reference the one formula's single-pair speed is set beside.
    """
    d1 = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    d2 = (q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2])
    r = (p0[0] - q0[0], p0[1] - q0[1], p0[2] - q0[2])
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    c = d1[0] * r[0] + d1[1] * r[1] + d1[2] * r[2]
    f = d2[0] * r[0] + d2[1] * r[1] + d2[2] * r[2]
    point_p, point_q = a <= collision._DEGENERATE_SQ, e <= collision._DEGENERATE_SQ
    safe_a, safe_e = (1.0 if point_p else a), (1.0 if point_q else e)
    n0 = d1[1] * d2[2] - d1[2] * d2[1]
    n1 = d1[2] * d2[0] - d1[0] * d2[2]
    n2 = d1[0] * d2[1] - d1[1] * d2[0]
    denom = n0 * n0 + n1 * n1 + n2 * n2
    if point_p:
        s = 0.0
    elif point_q:
        s = min(max(-c / safe_a, 0.0), 1.0)
    elif denom <= collision._PARALLEL_SIN_SQ * a * e:  # parallel: any s will do
        s = 0.0
    else:  # (-r x d2) . normal / |normal|^2
        m0 = -r[1] * d2[2] + r[2] * d2[1]
        m1 = -r[2] * d2[0] + r[0] * d2[2]
        m2 = -r[0] * d2[1] + r[1] * d2[0]
        s = min(max((m0 * n0 + m1 * n1 + m2 * n2) / denom, 0.0), 1.0)
    t_free = 0.0 if point_q else (b * s + f) / safe_e
    t = min(max(t_free, 0.0), 1.0)
    if not (point_p or t == t_free):
        s = min(max((b * t - c) / safe_a, 0.0), 1.0)
    g0 = r[0] + s * d1[0] - t * d2[0]
    g1 = r[1] + s * d1[1] - t * d2[1]
    g2 = r[2] + s * d1[2] - t * d2[2]
    return math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


def _branchy_capsules(arm: ArmModel, q) -> list:
    """Return the capsules of one state as ``[(start, end, radius)] * 3`` in floats."""
    t1, t2, d3 = (float(v) for v in q)
    h1 = float(arm.shoulder_height)
    h2 = h1 + arm.elbow_rise
    ex, ey = arm.l1 * math.cos(t1), arm.l1 * math.sin(t1)
    tx, ty = ex + arm.l2 * math.cos(t1 + t2), ey + arm.l2 * math.sin(t1 + t2)
    tip = h2 - d3
    (r00, r01, r02, o0), (r10, r11, r12, o1), (r20, r21, r22, o2) = arm.base[:3].tolist()

    def world(x, y, z):
        return (r00 * x + r01 * y + r02 * z + o0, r10 * x + r11 * y + r12 * z + o1,
                r20 * x + r21 * y + r22 * z + o2)
    elbow1, elbow2, tool2 = world(ex, ey, h1), world(ex, ey, h2), world(tx, ty, h2)
    return [(world(0.0, 0.0, h1), elbow1, arm.link_radius),
            (elbow2, tool2, arm.link_radius),
            (world(tx, ty, tip), world(tx, ty, tip + arm.quill_length), arm.quill_radius)]


def branchy_pair_distances(arm_a: ArmModel, q_a, arm_b: ArmModel, q_b) -> np.ndarray:
    """Return the (3, 3) capsule distances of one state pair by the branchy float formula."""
    caps_b = _branchy_capsules(arm_b, q_b)
    return np.array([[_branchy_segment(p0, p1, q0, q1) - rp - rq for q0, q1, rq in caps_b]
                     for p0, p1, rp in _branchy_capsules(arm_a, q_a)])


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


def time_solvers(quick: bool = False, log: Optional[Log] = None) -> Dict[str, object]:
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
    one = partial(collision.arm_pair_distances, arm, ql[0], right, qr[0])
    branchy = partial(branchy_pair_distances, arm, ql[0], right, qr[0])
    t_one, t_branchy = min_interleaved((one, branchy), max(n_call // 20, 50), 5 * repeat)
    branchy_all = np.array([branchy_pair_distances(arm, a, right, b) for a, b in zip(ql, qr)])
    same = float(np.max(np.abs(branchy_all - collision.arm_pair_distances(arm, ql, right, qr))))
    log(f'one state pair: the one formula {fmt_seconds(t_one)}, the branchy float formula '
        f'{fmt_seconds(t_branchy)}, ratio {t_branchy / t_one:.2f}; max diff {same:.1e} m')
    rows.append(_latency('capsule distances, one state pair (the one formula)', t_one,
                         t_branchy, 'branchy plain-float formula',
                         note=f'max diff over {len(ql)} pairs {same:.1e} m'))
    return {'rows': rows, 'sizes': {'n_vectorised': n_vec, 'n_calls': n_call,
                                    'n_state_pairs': n_pair, 'repeats': repeat},
            'quick': quick}


TARGETS = {
    'ik_latency': 5e-6,            # s, one target
    'ik_rate': 1e6,                # targets/s, vectorised
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""


@dataclass(frozen=True)
class Sizes:
    """How long the solvers are timed."""

    quick_solvers: bool = False      # few iterations: rough figures


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Time the motion core and its references."""
    return time_solvers(sizes.quick_solvers, progress.note)


def solver_row(data: dict, prefix: str) -> Optional[dict]:
    """Return the first row whose ``what`` starts with ``prefix`` (None if there is none)."""
    for r in data['rows']:
        if r['what'].startswith(prefix):
            return r
    return None


def summary(s: dict) -> Rows:
    """Return the summary row: IK latency, one target and vectorised."""
    one = solver_row(s, 'IK, one target')
    vec = next(r for r in s['rows'] if r['what'].startswith('IK,') and r['kind'] == 'rate')
    return [('IK latency', CLAIMS['ik_latency'].figure,
             f'{fmt_seconds(one["ours"])} one target; '
             f'{vec["ours"] / 1e6:.3g} M targets/s vectorised',
             '≤ 5 µs; ≥ 10⁶/s',
             met(one['ours'] <= TARGETS['ik_latency'] and vec['ours'] >= TARGETS['ik_rate']))]


def markdown(s: dict, results: dict) -> str:
    """Return the section's text: the claims, every timing beside its reference, the machine."""
    rows = []
    for r in s['rows']:
        d = display(r)
        claim = CLAIMS['ik_latency'].figure if r['what'] == 'IK, one target' else ''
        target = f'{r["target"]} {met(r["met"])}'.strip() if r['target'] else ''
        rows.append((r['what'], d['ours'], d['reference'], d['ratio'], r['note'], target,
                     claim))
    meta = results['meta']
    sizes = s['sizes']
    ik_one = solver_row(s, 'IK, one target')
    return '\n\n'.join([
        quote('ik_latency', 'solver_latency'),
        f'On {meta["cpu"]} ({meta["cores"]} cores), Python {meta["python"]}, numpy '
        f'{meta["numpy"]}; references in the same process on the same inputs. One call: '
        f'median of {sizes["repeats"]} loops of {sizes["n_calls"]} calls; N at once: median '
        f'of {sizes["repeats"]} calls on {sizes["n_vectorised"]} random states (arm-to-arm: '
        f'{sizes["n_state_pairs"]}). "ours vs reference" = how many times faster ours is '
        '(< 1: slower). The references without a batch API are called once per item. The '
        'seeds claim only an IK latency; the other rows have no claimed figure.',
        md_table(('what', 'ours', 'reference (same run)', 'ours vs reference',
                  'agreement / note', 'SPEC target', "seeds' claim"), rows),
        f'One IK call takes {ik_one["ours"] / 0.32e-3 * 100:.2g} % of the seeds\' claimed '
        f'0.32 ms and {ik_one["ours"] / 0.01 * 100:.2g} % of the 10 ms control period. '
        "Called one state at a time, numpy's per-call overhead makes the core slower than "
        "Pinocchio's and coal's C++; on N states at once it is faster than calling them in "
        'a loop. The machine may have been shared during the run (load at the start: '
        f'{num(meta["load_1min"], 2)}): absolute figures are noisy, ratios less so.'])


def figure(data: dict, path: Path) -> None:
    """Speed-up of the motion core over each reference, log scale."""
    rows = [r for r in data['rows'] if r['speedup'] is not None]
    fig, ax = canvas(8.0, 0.32 * len(rows) + 1.2)
    y = np.arange(len(rows))[::-1]
    vals = np.array([r['speedup'] for r in rows])
    ax.barh(y, vals, color=['tab:green' if v >= 1 else 'tab:red' for v in vals], alpha=0.7)
    ax.set_xscale('log')
    ax.set_xlim(min(vals.min(), 1.0) / 2, max(vals.max(), 1.0) * 4)
    ax.axvline(1.0, color='k', lw=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels([f'{r["what"]} (vs {r["reference_name"]})' for r in rows], fontsize=7)
    for yi, r in zip(y, rows):
        ax.text(r['speedup'], yi, f' {display(r)["ratio"]}', va='center', fontsize=7)
    ax.set_xlabel('how many times faster ours is (log; < 1 = slower)')
    ax.set_title('motion core vs references, same run', fontsize=10)
    save(fig, path)


SECTION = Section(
    key='solvers', title='solver speed vs reference implementations',
    heading='Solver speed, against reference implementations', measure=measure,
    markdown=markdown, summary=summary, figure=figure,
    figure_alt='speed-up over the references', full=Sizes(), smoke=Sizes(quick_solvers=True))
