"""Joint references: validation reasons, two-piece interpolation, velocity and accel. peaks."""
from hypothesis import given, settings, strategies as st
import numpy as np
import numpy.testing as npt
import pytest

from scara_collab.sim.reference import (
    hermite_coefficients, HermiteReference, model_peak_speed, peak_speed, TrajectoryError,
    validate_trajectory)

LOWER, UPPER = np.array([-2.618, -2.618, 0.0]), np.array([2.618, 2.618, 0.6])
VMAX = np.array([2.0, 2.0, 0.5])


def _check(t, q, qd=None, qdd=None):
    return validate_trajectory(t, q, qd, LOWER, UPPER, VMAX, qdd=qdd)


@given(st.lists(st.floats(0.05, 0.5), min_size=1, max_size=6),
       st.integers(0, 2 ** 31 - 1), st.booleans())
@settings(max_examples=50, deadline=None)
def test_spline_passes_through_points_with_their_velocities(steps, seed, accelerations):
    """The reference passes through every point with its velocity (hypothesis).

    Its acceleration is the derivative of its velocity, also with (arbitrary) accelerations
    given, and its speed stays within :func:`model_peak_speed`.
    """
    rng = np.random.default_rng(seed)
    t = 10.0 + np.concatenate(([0.0], np.cumsum(steps)))
    q = rng.uniform(-1.0, 1.0, size=(len(t), 3))
    qd = rng.uniform(-1.0, 1.0, size=(len(t), 3))
    qdd = rng.uniform(-20.0, 20.0, size=(len(t), 3)) if accelerations else None
    ref = HermiteReference(t, q, qd, qdd)
    for i in range(len(t) - 1):
        for side in (-1e-12, 1e-12):
            qi, qdi, _ = ref.sample(t[i] + side)
            npt.assert_allclose(qi, q[i], atol=1e-9)
            npt.assert_allclose(qdi, qd[i] if i or side > 0 else 0.0, atol=1e-6)
        # the acceleration is the derivative of the velocity (central difference)
        tm, h = t[i] + 0.37 * (t[i + 1] - t[i]), 1e-6
        qdd_fd = (ref.sample(tm + h)[1] - ref.sample(tm - h)[1]) / (2 * h)
        npt.assert_allclose(ref.sample(tm)[2], qdd_fd, rtol=1e-6, atol=1e-4)
    npt.assert_allclose(ref.sample(t[-1] - 1e-12)[0], q[-1], atol=1e-9)
    speed = np.abs([ref.sample(x)[1] for x in np.linspace(t[0], t[-1], 500)]).max(axis=0)
    assert np.all(speed <= model_peak_speed(t, q, qd, qdd) + 1e-9)


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
    qd = _check(t, q).qd
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


@pytest.mark.parametrize('ramp_start', [0.015, 0.0137, 0.0171])
def test_an_acceleration_that_switches_and_ramps_inside_a_sample_is_followed(ramp_start):
    """No acceleration, then -0.6 A from ``ramp_start`` ramping to -A at the next sample.

    Such segments (the planner's, where the acceleration switches and ramps inside one sample)
    are followed within A: the cubic or the switch model (the given accelerations held on both
    sides of the switch, plus a smoothstep) overshot A by 2.4 % for ``ramp_start = 0.015``; a
    scanned two-piece candidate is this profile, to the scan's step.
    """
    a_max, v_start, ramp_end = 6.0, 1.0, 0.02
    span = ramp_end - ramp_start

    def exact(time):
        s = np.clip(time - ramp_start, 0.0, span)
        after = np.maximum(time - ramp_end, 0.0)
        v_end = v_start - 0.8 * a_max * span
        q_end = v_start * ramp_end - a_max * (0.3 + 1.0 / 15.0) * span ** 2
        ramp = time < ramp_end
        return (np.where(ramp, v_start * np.minimum(time, ramp_end)
                         - a_max * (0.3 * s ** 2 + s ** 3 / (15.0 * span)),
                         q_end + v_end * after - 0.5 * a_max * after ** 2),
                np.where(ramp, v_start - a_max * (0.6 * s + 0.2 * s ** 2 / span),
                         v_end - a_max * after),
                np.where(time < ramp_start, 0.0,
                         np.where(ramp, -a_max * (0.6 + 0.4 * s / span), -a_max)))

    t = np.arange(0.0, 0.0501, 0.01)
    pos, vel, acc = (np.stack([x, 0.5 * x, 0.05 * x], axis=1) for x in exact(t))
    pos[:, 2] += 0.2
    args = validate_trajectory(t, pos, vel, LOWER, UPPER, VMAX, qdd=acc)
    ref = HermiteReference(*args)
    fine = np.linspace(t[0], t[-1], 50 * (len(t) - 1) + 1)
    q = np.array([ref.sample(x)[0] for x in fine])
    step = fine[1] - fine[0]
    assert np.max(np.abs(np.diff(q[:, 0], 2))) / step ** 2 <= a_max * (1 + 1e-6)
    npt.assert_allclose(q[:, 0], exact(fine)[0], atol=1e-5)


def _sampled(ref, times):
    """Return ``ref.sample`` at each of ``times`` as three ``(len(times), 3)`` arrays."""
    return tuple(np.array(x) for x in zip(*[ref.sample(x) for x in times]))


def _planned_lines(arm, seed, mode, count):
    from scara_collab.core.kinematics import fk
    from scara_collab.core.planning import plan_path
    rng = np.random.default_rng(seed)
    lines = 0
    while lines < count:
        q0 = rng.uniform(arm.lower * 0.9, arm.upper * 0.9)
        goal = fk(arm, rng.uniform(arm.lower * 0.9, arm.upper * 0.9))
        try:
            tr = plan_path(arm, q0, goal, 'world', mode)
        except ValueError:
            continue
        lines += 1
        yield tr


@pytest.mark.parametrize('arm_index, seed, mode, count', [
    (0, 1, 'line', 60), (1, 2, 'line_or_joint', 20)])
def test_planned_lines_stay_within_the_limits_between_their_samples(arm_index, seed, mode,
                                                                    count):
    """What the simulator executes from planned lines, resampled 50x: within the limits.

    The planner's lines are time-optimal (bang-bang), sampled every 10 ms. Over random lines
    the reference's velocity stays within 0.5 % of the limit and its acceleration (second
    differences of the positions at 0.2 ms, and the feed-forward it returns) within 1 % (the
    cubic reached 1.57x; the cubic or switch model 1.043x, where the acceleration ramps and
    switches inside one sample; now 1.0017x over 100 lines). The velocity it returns peaks
    where :func:`model_peak_speed`, which :func:`validate_trajectory` checks, says.
    """
    from scara_collab.core.model import load_cell
    arm = load_cell().arms[arm_index]
    worst_v, worst_a, worst_ff = [], [], []
    for tr in _planned_lines(arm, seed, mode, count):
        args = validate_trajectory(tr.t, tr.q, tr.qd, arm.lower, arm.upper, arm.max_velocity,
                                   qdd=tr.qdd)
        ref = HermiteReference(*args)
        fine = np.linspace(tr.t[0], tr.t[-1], 50 * (len(tr.t) - 1) + 1)
        q, qd, qdd = _sampled(ref, fine)
        step = fine[1] - fine[0]
        worst_v.append(np.max(np.abs(np.diff(q, axis=0)) / step / arm.max_velocity))
        worst_a.append(np.max(np.abs(np.diff(q, 2, axis=0)) / step ** 2 / arm.max_acceleration))
        worst_ff.append(np.max(np.abs(qdd) / arm.max_acceleration))
        sampled, peak = np.abs(qd).max(axis=0), model_peak_speed(*args)
        assert np.all(sampled <= peak + 1e-9)  # the check holds the peak between the points
        assert np.all(sampled >= peak - arm.max_acceleration * step)
    assert max(worst_v) <= 1.005, max(worst_v)
    worst, median = max(worst_a), float(np.median(worst_a))
    assert worst <= 1.01 and median <= 1.001, (worst, median)
    assert max(worst_ff) <= 1.01, max(worst_ff)


def test_planned_references_are_continuous_and_return_their_derivatives():
    """Planned references: continuous at the samples and returning their own derivatives.

    Position and velocity are continuous where the pieces of two segments meet; the velocity
    and acceleration :meth:`HermiteReference.sample` returns are the derivatives of the
    position and velocity it returns (central differences, 0.1 us).
    """
    from scara_collab.core.model import load_cell
    arm = load_cell().arms[0]
    for tr in _planned_lines(arm, 3, 'line', 4):
        ref = HermiteReference(*validate_trajectory(
            tr.t, tr.q, tr.qd, arm.lower, arm.upper, arm.max_velocity, qdd=tr.qdd))
        for side in (-1e-9, 1e-9):
            q, qd, _ = _sampled(ref, tr.t[1:-1] + side)
            npt.assert_allclose(q, tr.q[1:-1], atol=1e-8)
            npt.assert_allclose(qd, tr.qd[1:-1], atol=1e-7)
        eps = 1e-7
        times = np.linspace(tr.t[0], tr.t[-1], 20 * (len(tr.t) - 1) + 1)[1:-1] + 3.3e-5
        q0, v0, a0 = _sampled(ref, times - eps)
        q1, v1, a1 = _sampled(ref, times + eps)
        _, v, a = _sampled(ref, times)
        npt.assert_allclose((q1 - q0) / (2 * eps), v, atol=1e-6)
        # the acceleration may jump where two pieces meet: the velocity's slope across it lies
        # between both sides', and the acceleration returned is one side's
        tol = 1e-3 * arm.max_acceleration
        slope = (v1 - v0) / (2 * eps)
        assert np.all((slope >= np.minimum(a0, a1) - tol) & (slope <= np.maximum(a0, a1) + tol))
        assert np.all(np.minimum(np.abs(a - a0), np.abs(a - a1)) <= tol)
