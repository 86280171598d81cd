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
    """The spline passes through every point with its velocity (hypothesis).

    Its acceleration is the derivative of its velocity.
    """
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
    """Before the first point and after the last the reference holds those points at rest."""
    t, q = [1.0, 2.0], [[0.0, 0.0, 0.1], [0.5, -0.5, 0.2]]
    ref = HermiteReference(*_check(t, q)[:3])
    for time, expect in ((0.0, q[0]), (5.0, q[1])):
        pos, vel, acc = ref.sample(time)
        npt.assert_allclose(pos, expect)
        assert not vel.any() and not acc.any()


def test_default_velocities_are_central_differences_and_zero_at_the_ends():
    """Without given velocities the inner ones are central differences, the end ones zero."""
    t = np.array([0.0, 1.0, 2.0, 4.0])
    q = np.array([[0.0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [1.2, 0, 0]])
    _, _, qd, _ = _check(t, q)
    npt.assert_allclose(qd[:, 0], [0.0, 0.5, 0.7 / 3.0, 0.0])


def test_peak_speed_finds_the_maximum_inside_a_segment():
    """The peak speed inside a segment is found (1.5x the mean for a smoothstep)."""
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
    """Each malformed or out-of-limits trajectory is refused, saying why and where."""
    with pytest.raises(TrajectoryError, match=reason):
        _check(t, q)


def test_given_velocities_above_the_limit_are_refused():
    """Given velocities above the limit, and non-finite accelerations, are refused."""
    with pytest.raises(TrajectoryError, match='velocity of joint 3'):
        _check([0.0, 1.0], np.zeros((2, 3)), qd=[[0, 0, 0], [0, 0, 0.6]])
    with pytest.raises(TrajectoryError, match='accelerations has a non-finite'):
        _check([0.0, 1.0], np.zeros((2, 3)), qdd=[[0, 0, 0], [0, np.nan, 0]])


@pytest.mark.parametrize('switch', [0.0125, 0.0151, 0.018])
def test_a_bang_bang_plan_is_followed_exactly_between_its_samples(switch):
    """Accelerate at +A, then brake at -A from ``switch`` s: the switch falls between samples.

    A cubic through the samples' positions and velocities overshoots A by up to 1.5x; the
    switch model reproduces the plan (positions to 1e-12, accelerations exactly A).
    """
    a_max, dt = 6.0, 0.01
    t = np.arange(0.0, 0.0401, dt)

    def exact(time):
        up = np.minimum(time, switch)
        down = np.maximum(time - switch, 0.0)
        v_top = a_max * up
        return (0.5 * a_max * up ** 2 + v_top * down - 0.5 * a_max * down ** 2,
                v_top - a_max * down, np.where(time < switch, a_max, -a_max))

    pos, vel, acc = (np.stack([x, -x, 0.1 * x], axis=1) for x in exact(t))
    pos[:, 2] += 0.2  # the quill inside its limits
    lower, upper, vmax = np.array([-3, -3, 0.0]), np.array([3, 3, 0.6]), np.array([2, 2, 0.5])
    args = validate_trajectory(t, pos, vel, lower, upper, vmax, qdd=acc)
    fine = np.linspace(t[0], t[-1], 50 * (len(t) - 1) + 1)
    ref = HermiteReference(*args)
    q = np.array([ref.sample(x)[0] for x in fine])
    npt.assert_allclose(q[:, 0], exact(fine)[0], atol=1e-12)
    npt.assert_allclose([ref.sample(x)[2][0] for x in fine[1:-1]], exact(fine[1:-1])[2],
                        atol=1e-9)
    step = fine[1] - fine[0]
    assert np.max(np.abs(np.diff(q[:, 0], 2))) / step ** 2 <= a_max * (1 + 1e-6)
    cubic = HermiteReference(t, pos, vel)  # no accelerations given: the old reference
    q3 = np.array([cubic.sample(x)[0][0] for x in fine])
    assert np.max(np.abs(np.diff(q3, 2))) / step ** 2 > 1.1 * a_max


def test_planned_lines_stay_within_the_limits_between_their_samples():
    """What the simulator executes from planned lines, resampled 50x: within the limits.

    The planner's lines are time-optimal (bang-bang), sampled every 10 ms. Over 60 random
    lines the reference's velocity stays within 0.5 % of the limit and its acceleration
    (second differences of the positions at 0.2 ms) within 5 % (the cubic reached 1.57x;
    what is left are segments whose acceleration ramps and switches inside one sample).
    """
    from scara_collab.core.kinematics import fk
    from scara_collab.core.model import load_cell
    from scara_collab.core.planning import plan_path
    arm = load_cell().arms[0]
    rng = np.random.default_rng(1)
    worst_v, worst_a, lines = [], [], 0
    while lines < 60:
        q0 = rng.uniform(arm.lower * 0.9, arm.upper * 0.9)
        goal = fk(arm, rng.uniform(arm.lower * 0.9, arm.upper * 0.9))
        try:
            tr = plan_path(arm, q0, goal, 'world', 'line')
        except ValueError:
            continue
        lines += 1
        args = validate_trajectory(tr.t, tr.q, tr.qd, arm.lower, arm.upper, arm.max_velocity,
                                   qdd=tr.qdd)
        ref = HermiteReference(*args)
        fine = np.linspace(tr.t[0], tr.t[-1], 50 * (len(tr.t) - 1) + 1)
        q = np.array([ref.sample(x)[0] for x in fine])
        step = fine[1] - fine[0]
        worst_v.append(np.max(np.abs(np.diff(q, axis=0)) / step / arm.max_velocity))
        worst_a.append(np.max(np.abs(np.diff(q, 2, axis=0)) / step ** 2 / arm.max_acceleration))
    assert max(worst_v) <= 1.005, max(worst_v)
    worst, median = max(worst_a), float(np.median(worst_a))
    assert worst <= 1.05 and median <= 1.005, (worst, median)
