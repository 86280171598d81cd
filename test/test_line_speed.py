"""The float loop of ``follow_line`` gives the numpy DLS loop's results, near singularities too."""
from dataclasses import replace

import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core import trajectory
from scara_collab.core.kinematics import (
    base_to_world, dls_damping, dls_solve, fk, ik, manipulability)
from scara_collab.core.model import load_cell

CELL = load_cell()
THRESHOLD, MAX_DAMPING = 0.5, 0.15


def _reference_follow_line(arm, q0, points, velocity_dir, threshold, max_damping,
                           iterations=3):
    """Run ``follow_line`` on its numpy loop alone: DLS Newton steps per point, world frame."""
    q = trajectory._follow_line_numpy(arm, q0, points, threshold, max_damping, iterations)
    return q, dls_solve(arm, q, np.broadcast_to(velocity_dir, q.shape), threshold, max_damping)


def _rot(axis, angle):
    """Return the 3x3 rotation about a unit ``axis`` by ``angle`` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def _with_base(arm, rot, shift=(0.0, 0.0, 0.0)):
    base = np.array(arm.base)
    base[:3, :3] = rot
    base[:3, 3] += shift
    base.setflags(write=False)
    return replace(arm, base=base)


# both arms of the cell, plus the leader on a base turned by pi about z and on a tilted base
ARMS = {arm.name: arm for arm in CELL.arms}
ARMS['yaw_pi'] = _with_base(CELL.leader, _rot([0, 0, 1], np.pi), (0.3, -0.1, 0.0))
ARMS['tilted'] = _with_base(CELL.follower, _rot([0.3, -0.5, 1.0], 2.1))


def _singular_lines(arm, rng, count):
    """Random start states and straight lines near the singularities of ``arm``.

    Only lines :func:`line_move` hands to ``follow_line``: both ends inside the reach window
    and no point inside the inner reach (beyond the outer reach the damped iteration has no
    solution to converge to, spins the elbow and amplifies rounding chaotically). Half start
    almost stretched (|theta2| 0.41..0.6, manipulability 0.6..0.85, just above the damping
    threshold), half run 0.55..0.66 m from the shoulder axis, where the folded arm is damped.
    """
    out = []
    while len(out) < count:
        if len(out) % 2 == 0:  # almost stretched start, line to a random reachable point
            q0 = np.array([rng.uniform(-np.pi, np.pi),
                           rng.choice([-1, 1]) * rng.uniform(0.41, 0.6), rng.uniform(0.0, 0.6)])
            a = fk(arm, q0, frame='base')
            b = np.r_[rng.uniform(-2.45, 2.45, 2), a[2] + rng.uniform(-0.3, 0.3)]
        else:  # a line passing close to the inner reach: folded arm, damped
            ang, d = rng.uniform(-np.pi, np.pi), rng.uniform(arm.reach_min, 0.66)
            normal = np.array([np.cos(ang), np.sin(ang)])
            along = np.array([-np.sin(ang), np.cos(ang)])
            a = np.r_[d * normal - rng.uniform(0.3, 2.0) * along, rng.uniform(-0.1, 0.4)]
            b = np.r_[d * normal + rng.uniform(0.3, 2.0) * along, rng.uniform(-0.1, 0.4)]
            q0 = ik(arm, a, frame='base').q
        s = np.linspace(0.0, 1.0, int(rng.integers(150, 400)))
        pts = a + s[:, None] * (b - a)
        r = np.hypot(pts[:, 0], pts[:, 1])
        if np.isnan(q0).any() or r.min() < arm.reach_min or r.max() > arm.reach_max:
            continue
        pa, pb = base_to_world(arm, a), base_to_world(arm, b)
        out.append((q0, pa + s[:, None] * (pb - pa), pb - pa))
    return out


@pytest.mark.parametrize('name', list(ARMS))
def test_float_loop_matches_the_numpy_loop_near_singularities(name):
    """Near singularities ``follow_line`` gives the numpy loop's results to 1e-10.

    For both arms of the cell, a base turned about z and a tilted one.
    """
    arm = ARMS[name]
    rng = np.random.default_rng(list(ARMS).index(name) + 11)
    damped = 0
    for q0, points, direction in _singular_lines(arm, rng, 16):
        q, dq = trajectory.follow_line(arm, q0, points, direction, THRESHOLD, MAX_DAMPING)
        q_ref, dq_ref = _reference_follow_line(arm, q0, points, direction, THRESHOLD,
                                               MAX_DAMPING)
        assert q.shape == q_ref.shape and dq.shape == dq_ref.shape
        assert_allclose(q, q_ref, rtol=0, atol=1e-10)
        assert_allclose(dq, dq_ref, rtol=0, atol=1e-10)
        damped += bool(np.min(manipulability(arm, q)) < THRESHOLD)
    assert damped >= 5, 'the lines exercise the damped region'


def test_other_iteration_counts_and_damping_match_too():
    """Other iteration counts, thresholds and damping limits give the numpy loop's results."""
    arm = CELL.follower
    rng = np.random.default_rng(7)
    # (iterations, threshold, max damping); a threshold of 0.9 damps the stretched starts too
    settings = [(1, 0.5, 0.15), (2, 0.9, 0.3), (5, 0.2, 0.05), (0, 0.5, 0.15), (3, 0.9, 0.15)]
    for (q0, points, direction), (iterations, thr, lam) in zip(
            _singular_lines(arm, rng, len(settings)), settings):
        got = trajectory.follow_line(arm, q0, points, direction, thr, lam, iterations)
        ref = _reference_follow_line(arm, q0, points, direction, thr, lam, iterations)
        for a, b in zip(got, ref):
            assert_allclose(a, b, rtol=0, atol=1e-10)


def test_the_scalar_damping_is_dls_damping():
    """The scalar damping of the float loop equals :func:`dls_damping`."""
    for w in (0.0, 1e-9, 0.1, 0.25, 0.4999999, 0.5, 0.7, 2.5):
        for thr, lam in ((0.5, 0.15), (1.0, 0.3)):
            assert trajectory._scalar_damping(w, thr, lam) == pytest.approx(
                float(dls_damping(w, thr, lam)), abs=1e-15)


def _outcome(fn):
    try:
        return fn()
    except Exception as exc:  # the fallback must raise what numpy raised
        return type(exc)


def test_fallbacks_give_the_numpy_loop_results():
    """Where the float loop cannot go, the fallback gives (or raises) what numpy does."""
    arm = CELL.leader
    q0 = np.array([0.4, 0.0, 0.2])  # exactly stretched
    a = fk(arm, q0)
    points = a + np.linspace(0.0, 1.0, 50)[:, None] * np.array([-0.8, 0.3, 0.1])
    direction = points[-1] - points[0]
    # undamped at an exact singularity: the float solve divides by zero, numpy decides
    got = _outcome(lambda: trajectory.follow_line(arm, q0, points, direction, 0.5, 0.0))
    ref = _outcome(lambda: _reference_follow_line(arm, q0, points, direction, 0.5, 0.0))
    if isinstance(ref, tuple):
        for x, y in zip(got, ref):
            assert_allclose(x, y, rtol=0, atol=0, equal_nan=True)
    else:
        assert got is ref
    # a base rotation that is not orthogonal (not a rigid pose): the numpy loop is used as is
    skewed = _with_base(arm, np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    q0 = np.array([0.4, 0.3, 0.2])
    points = fk(skewed, q0) + np.linspace(0.0, 1.0, 50)[:, None] * np.array([-0.8, 0.3, 0.1])
    got = trajectory.follow_line(skewed, q0, points, direction, 0.5, 0.15)
    ref = _reference_follow_line(skewed, q0, points, direction, 0.5, 0.15)
    for x, y in zip(got, ref):
        assert np.array_equal(x, y)


# base-frame lines that line_move integrates sequentially (follow_line), found by a search
SEQUENTIAL_LINES = [
    ('scara_left', (1.422, 1.971, -0.064), (0.763, -2.144, 0.191)),
    ('scara_left', (-0.714, 2.332, 0.266), (1.207, -0.128, 0.368)),
    ('scara_right', (-0.88, 2.194, 0.044), (2.044, -0.205, 0.323)),
    ('scara_right', (2.365, 0.483, 0.166), (0.273, -2.325, 0.007)),
]


@pytest.mark.parametrize('name, a, b', SEQUENTIAL_LINES)
def test_line_move_is_unchanged_on_the_sequential_path(monkeypatch, name, a, b):
    """``line_move`` gives the numpy loop's result on its sequential path."""
    arm = CELL.arm(name)
    q0 = ik(arm, base_to_world(arm, np.array(a))).unwrap()
    target = base_to_world(arm, np.array(b))
    calls = []
    fast = trajectory.follow_line

    def spy(*args, **kwargs):
        calls.append(len(args[2]))
        return fast(*args, **kwargs)

    monkeypatch.setattr(trajectory, 'follow_line', spy)
    got = trajectory.line_move(arm, q0, target)
    assert calls, '_line_path took the sequential path'
    monkeypatch.setattr(trajectory, 'follow_line', _reference_follow_line)
    ref = trajectory.line_move(arm, q0, target)
    assert got.t.shape == ref.t.shape
    for field in ('t', 'q', 'qd', 'qdd', 'p'):
        assert_allclose(getattr(got, field), getattr(ref, field), rtol=0, atol=1e-10,
                        err_msg=field)


def _reference_scaling(s, dq, d2q, vmax, amax):
    """Run the phase-plane passes of ``time_optimal_scaling`` with the builtin max and min."""
    xmax = trajectory._max_sdot_sq(dq, d2q, vmax, amax).tolist()
    ds = np.diff(s).tolist()
    c, d = trajectory._accel_coefficients(dq, d2q, amax)
    c, d = c.tolist(), d.tolist()
    m = len(s)
    back = [0.0] * m
    for i in range(m - 2, -1, -1):
        xb = back[i + 1]
        umin = max(c[i + 1][k] + d[i + 1][k] * xb for k in range(3))
        back[i] = max(0.0, min(xmax[i], xb - 2.0 * ds[i] * umin))
    x = [0.0] * m
    for i in range(m - 1):
        umax = min(d[i][k] * x[i] - c[i][k] for k in range(3))
        x[i + 1] = max(0.0, min(back[i + 1], xmax[i + 1], x[i] + 2.0 * ds[i] * umax))
    return np.sqrt(np.maximum(np.asarray(x), 0.0))


def test_the_written_out_phase_plane_passes_equal_the_builtin_max_min_exactly():
    """Random paths (joints that stay, zero and large curvature): equal to the last bit."""
    arm = CELL.arms[0]
    rng = np.random.default_rng(3)
    for k in range(60):
        m = int(rng.integers(50, 600))
        s = np.linspace(0.0, 1.0, m)
        dq = rng.normal(size=(m, 3)) * rng.uniform(0.1, 3.0)
        if k % 4 == 0:
            dq[:, k % 3] = 0.0  # a joint that does not move bounds nothing
        d2q = rng.normal(size=(m, 3)) * rng.uniform(0.0, 5.0) * (k % 5 != 0)
        got = trajectory.time_optimal_scaling(s, dq, d2q, arm.max_velocity, arm.max_acceleration)
        want = _reference_scaling(s, dq, d2q, arm.max_velocity, arm.max_acceleration)
        assert np.array_equal(got, want), k
