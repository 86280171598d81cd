"""Joint references: validation reasons, cubic Hermite interpolation, velocity peaks."""
from hypothesis import given, settings, strategies as st
import numpy as np
import numpy.testing as npt
import pytest

from scara_collab.sim.reference import (
    hermite_coefficients, HermiteReference, peak_speed, TrajectoryError, validate_trajectory)

LOWER, UPPER = np.array([-2.618, -2.618, 0.0]), np.array([2.618, 2.618, 0.6])
VMAX = np.array([2.0, 2.0, 0.5])


def _check(t, q, qd=None, qdd=None):
    return validate_trajectory(t, q, qd, LOWER, UPPER, VMAX, qdd=qdd)


@given(st.lists(st.floats(0.05, 0.5), min_size=1, max_size=6),
       st.integers(0, 2 ** 31 - 1))
@settings(max_examples=50, deadline=None)
def test_spline_passes_through_points_with_their_velocities(steps, seed):
    rng = np.random.default_rng(seed)
    t = 10.0 + np.concatenate(([0.0], np.cumsum(steps)))
    q = rng.uniform(-1.0, 1.0, size=(len(t), 3))
    qd = rng.uniform(-1.0, 1.0, size=(len(t), 3))
    ref = HermiteReference(t, q, qd)
    for i in range(len(t) - 1):
        qi, qdi, _ = ref.sample(t[i] + 1e-12)
        npt.assert_allclose(qi, q[i], atol=1e-9)
        npt.assert_allclose(qdi, qd[i], atol=1e-6)
        # the acceleration is the derivative of the velocity (central difference)
        tm, h = 0.5 * (t[i] + t[i + 1]), 1e-6
        qdd_fd = (ref.sample(tm + h)[1] - ref.sample(tm - h)[1]) / (2 * h)
        npt.assert_allclose(ref.sample(tm)[2], qdd_fd, atol=1e-4)
    npt.assert_allclose(ref.sample(t[-1] - 1e-12)[0], q[-1], atol=1e-9)


def test_before_and_after_the_trajectory_it_holds_at_rest():
    t, q = [1.0, 2.0], [[0.0, 0.0, 0.1], [0.5, -0.5, 0.2]]
    ref = HermiteReference(*_check(t, q)[:3])
    for time, expect in ((0.0, q[0]), (5.0, q[1])):
        pos, vel, acc = ref.sample(time)
        npt.assert_allclose(pos, expect)
        assert not vel.any() and not acc.any()


def test_default_velocities_are_central_differences_and_zero_at_the_ends():
    t = np.array([0.0, 1.0, 2.0, 4.0])
    q = np.array([[0.0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [1.2, 0, 0]])
    _, _, qd, _ = _check(t, q)
    npt.assert_allclose(qd[:, 0], [0.0, 0.5, 0.7 / 3.0, 0.0])


def test_peak_speed_finds_the_maximum_inside_a_segment():
    t = np.array([0.0, 1.0])
    q = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    qd = np.zeros((2, 3))  # smoothstep: peak 1.5 x the mean speed at mid-segment
    npt.assert_allclose(peak_speed(t, qd, *hermite_coefficients(t, q, qd)), [1.5, 0, 0])


@pytest.mark.parametrize('t, q, reason', [
    ([], np.zeros((0, 3)), 'non-empty'),
    ([[0.0, 1.0]], np.zeros((2, 3)), 'non-empty'),
    ([0.0, 1.0], np.zeros((3, 3)), 'shape'),
    ([0.0, 'x'], np.zeros((2, 3)), 'not numeric'),
    ([0.0, np.inf], np.zeros((2, 3)), 'times has a non-finite value at point 1'),
    ([0.0, 1.0, 1.0], np.zeros((3, 3)), 'point 2 is at 1.000000 s, not after'),
    ([0.0, 1.0], [[0, 0, 0], [0, 0, -0.1]], 'joint 3 at point 1 is -0.100000'),
    ([0.0, 0.5], [[0, 0, 0], [0.9, 0, 0]], 'velocity of joint 1 reaches 2.7'),
])
def test_refusals_say_why(t, q, reason):
    with pytest.raises(TrajectoryError, match=reason):
        _check(t, q)


def test_given_velocities_above_the_limit_are_refused():
    with pytest.raises(TrajectoryError, match='velocity of joint 3'):
        _check([0.0, 1.0], np.zeros((2, 3)), qd=[[0, 0, 0], [0, 0, 0.6]])
    with pytest.raises(TrajectoryError, match='accelerations has a non-finite'):
        _check([0.0, 1.0], np.zeros((2, 3)), qdd=[[0, 0, 0], [0, np.nan, 0]])
