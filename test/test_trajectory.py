"""Trajectories: the straight line stays on the line, limits hold, joint moves are the baseline."""
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core.kinematics import base_to_world, fk, ik, ik_both, IKError
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import (
    interp_rows, joint_move, line_move, path_metrics, resolved_rate, segment_deviation)

CELL = load_cell()
ARM = CELL.leader
# The design documents' "standard 1.5 m move ... to the conveyor centre": from world (3.2, -0.9)
# to the belt centre line at (2.0, 0.0), 0.1 m above an item's top.
SEEDS_MOVE = (np.array([3.2, -0.9, 0.4]), np.array([2.0, 0.0, 0.4]))


def _limits_hold(traj, arm=ARM):
    assert np.all(np.abs(traj.qd) <= arm.max_velocity * (1 + 1e-6))
    assert np.all(np.abs(traj.qdd) <= arm.max_acceleration * (1 + 1e-6))
    assert np.all(traj.q >= arm.lower - 1e-9) and np.all(traj.q <= arm.upper + 1e-9)


def _well_formed(traj, dt=0.01):
    assert traj.t[0] == 0.0 and np.all(np.diff(traj.t) > 0)
    assert np.diff(traj.t).max() <= dt + 1e-12
    assert_allclose(traj.qd[[0, -1]], 0.0, atol=1e-12)  # starts and ends at rest


def test_the_design_documents_move_is_straight_to_1e6_and_joint_interpolation_is_not():
    """The design documents' 1.5 m move as a line stays within 1e-6 m of the segment.

    Joint interpolation between the same ends arcs more than 5 cm off and is longer.
    """
    p0, p1 = SEEDS_MOVE
    assert np.linalg.norm(p1 - p0) == pytest.approx(1.5)
    q0 = ik(ARM, p0).unwrap()
    line = line_move(ARM, q0, p1)
    m = path_metrics(line, p0, p1)
    assert m.max_deviation <= 1e-6
    assert m.path_length == pytest.approx(1.5, abs=1e-6)
    assert_allclose(line.p[-1], p1, atol=1e-9)
    _well_formed(line)
    _limits_hold(line)
    joint = joint_move(ARM, q0, ik(ARM, p1, q0).unwrap())
    mj = path_metrics(joint, p0, p1)
    _well_formed(joint)
    _limits_hold(joint)
    assert mj.max_deviation > 0.05, 'joint interpolation arcs away from the line'
    assert mj.path_length > m.path_length
    print(f'\nseeds 1.5 m move: line dev {m.max_deviation:.2e} m in {m.duration:.3f} s; '
          f'joint interpolation dev {mj.max_deviation:.3f} m, {mj.path_length:.3f} m long, '
          f'{mj.duration:.3f} s')


def test_time_optimal_joint_move_matches_the_trapezoid_bound():
    """A joint move takes the trapezoid bound of its longest joint; all joints move in step."""
    q0, q1 = np.array([0.0, 1.0, 0.0]), np.array([1.5, 0.5, 0.3])
    traj = joint_move(ARM, q0, q1)
    delta, v, a = 1.5, ARM.max_velocity[0], ARM.max_acceleration[0]
    bound = delta / v + v / a if delta > v * v / a else 2 * np.sqrt(delta / a)
    assert traj.duration == pytest.approx(bound, rel=0.02)
    _limits_hold(traj)
    # joints move in step: every joint is at the same fraction of its travel
    frac = (traj.q - q0) / (q1 - q0)
    assert_allclose(frac, np.repeat(frac[:, :1], 3, axis=1), atol=1e-9)


def test_line_moves_saturate_a_limit():
    """A time-optimal line move drives some joint to within 5 % of a limit."""
    p0, p1 = SEEDS_MOVE
    traj = line_move(ARM, ik(ARM, p0).unwrap(), p1)
    ratio = max(np.max(np.abs(traj.qd) / ARM.max_velocity),
                np.max(np.abs(traj.qdd) / ARM.max_acceleration))
    assert ratio > 0.95, 'time-optimal: some joint works at its limit'


def test_random_line_moves_stay_straight_and_within_limits():
    """Random line moves stay straight to 1e-6 m and within the limits, or are refused."""
    rng = np.random.default_rng(4)
    done = 0
    while done < 25:
        a, b = ARM.base_position + np.c_[rng.uniform(-2.4, 2.4, 2), rng.uniform(-2.4, 2.4, 2),
                                         rng.uniform(-0.5, 0.0, 2)]
        q0 = ik(ARM, a)
        if not q0.ok or not ik(ARM, b, q0.q).ok:
            continue
        try:
            traj = line_move(ARM, q0.q, b)
        except IKError as exc:  # legitimately refused: the line would leave the limits
            assert 'joint limit' in str(exc)
            continue
        done += 1
        assert path_metrics(traj, a, b).max_deviation <= 1e-6
        _limits_hold(traj)
        _well_formed(traj)


def test_bad_targets_are_refused_with_reasons():
    """Unreachable, non-finite, inner-hole and out-of-limit moves are refused with reasons."""
    q0 = ik(ARM, SEEDS_MOVE[0]).unwrap()
    with pytest.raises(IKError, match='beyond the outer reach'):
        line_move(ARM, q0, [6.0, -2.0, 0.3])
    with pytest.raises(IKError, match='non-finite'):
        line_move(ARM, q0, [np.nan, 0.0, 0.3])
    # a line through the hole around the shoulder cannot be straight
    start = ARM.base_position + [1.0, 0.2, 0.2]
    with pytest.raises(IKError, match='inner reach'):
        line_move(ARM, ik(ARM, start).unwrap(), ARM.base_position + [-1.0, 0.1, 0.2])
    with pytest.raises(IKError, match='joint limit'):
        joint_move(ARM, q0, [3.0, 0.0, 0.0])
    with pytest.raises(IKError, match='outside the reach window'):  # stretched out: singular
        line_move(ARM, np.zeros(3), SEEDS_MOVE[1])


def test_zero_length_move_is_a_hold():
    """A move to where the tool already is holds the joints."""
    q0 = ik(ARM, SEEDS_MOVE[0]).unwrap()
    traj = line_move(ARM, q0, SEEDS_MOVE[0])
    assert_allclose(traj.q, np.broadcast_to(q0, traj.q.shape), atol=1e-12)


def test_segment_deviation():
    """Point-to-segment distances are right inside the segment and beyond its ends."""
    a, b = np.zeros(3), np.array([1.0, 0, 0])
    pts = np.array([[0.5, 0.2, 0], [-1.0, 0, 0], [2.0, 0, 0.5]])
    assert_allclose(segment_deviation(pts, a, b), [0.2, 1.0, np.hypot(1.0, 0.5)])


def _radial_study(max_damping):
    """Constant 0.3 m/s radially out to the outer singularity (a kinematic study)."""
    a, b = np.array([1.5, 0.0, 0.4]), np.array([2.5, 0.0, 0.4])
    dt, duration = 0.001, 1.0 / 0.3
    s = np.linspace(0.0, 1.0, int(duration / dt) + 1)
    p_ref = base_to_world(ARM, a + s[:, None] * (b - a))
    v_ref = np.broadcast_to((b - a) / duration, p_ref.shape)
    return resolved_rate(ARM, ik_both(ARM, p_ref[0])[0], p_ref, v_ref, dt, gain=5.0,
                         dls_max_damping=max_damping)


def test_dls_keeps_joint_speed_bounded_into_a_singularity():
    """Into the outer singularity pinv asks over 3x the speed limit; DLS stays under it."""
    plain = np.abs(_radial_study(0.0)).max()
    damped = np.abs(_radial_study(0.15)).max()
    assert plain > 3 * ARM.max_velocity[0], 'the pseudo-inverse asks for huge speeds'
    assert damped <= ARM.max_velocity[0], 'DLS keeps the joints under 2 rad/s'
    print(f'\nradial approach to the outer singularity at 0.3 m/s: pinv peak {plain:.2f} '
          f'rad/s, DLS peak {damped:.2f} rad/s')


def test_grazing_the_inner_circle_needs_no_damping():
    """Graze the inner circle: bounded joint speeds even undamped.

    A straight line tangent to the inner circle asks no radial motion at the closest point, so
    joint speeds stay bounded even without damping (reported, not hidden).
    """
    a, b = np.array([0.6, 0.505, 0.4]), np.array([-0.6, 0.505, 0.4])
    dt, duration = 0.001, 1.2 / 0.3
    s = np.linspace(0.0, 1.0, int(duration / dt) + 1)
    p_ref = base_to_world(ARM, a + s[:, None] * (b - a))
    v_ref = np.broadcast_to((b - a) / duration, p_ref.shape)
    q0 = ik_both(ARM, p_ref[0])[0]
    for lam in (0.0, 0.15):
        qd = resolved_rate(ARM, q0, p_ref, v_ref, dt, gain=5.0, dls_max_damping=lam)
        assert np.abs(qd).max() < ARM.max_velocity[0]
        q = q0 + np.cumsum(qd, axis=0) * dt
        assert np.linalg.norm(fk(ARM, q) - p_ref, axis=1).max() < 0.02


def test_interp_rows_is_numpy_interp_per_column_with_held_ends():
    """Each column is ``numpy.interp``: exact at the knots, held outside, scalar -> one row."""
    rng = np.random.default_rng(4)
    xp = np.cumsum(rng.uniform(0.1, 1.0, 12))
    fp = rng.normal(size=(12, 3))
    x = np.concatenate([xp, rng.uniform(xp[0] - 1.0, xp[-1] + 1.0, 200)])
    got = interp_rows(x, xp, fp)
    assert got.shape == (212, 3)
    assert np.array_equal(got[:12], fp)
    for j in range(3):
        assert np.array_equal(got[:, j], np.interp(x, xp, fp[:, j]))
    assert np.array_equal(interp_rows(xp[0] - 5.0, xp, fp), fp[0])  # held before the start
    assert np.array_equal(interp_rows(xp[-1] + 5.0, xp, fp), fp[-1])  # ... and after the end
    assert interp_rows(0.3, [1.0], [[1.0, 2.0]]).tolist() == [1.0, 2.0]  # a single knot
    traj = joint_move(ARM, [0.0, 1.0, 0.1], [0.5, 0.5, 0.3])
    assert np.array_equal(traj.sample(traj.t), traj.q)
