"""Speed and separation monitoring's formulas and the per-arm assessment, without ROS."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core import collision, safety, ssm
from scara_collab.core.config import load_config


@pytest.fixture(scope='module')
def params():
    """Return the monitor's numbers from config/people.yaml."""
    return ssm.SsmParams.from_config(load_config('people'))


def person(x, y, vx=0.0, vy=0.0, radius=0.25):
    """Return a person column at (x, y)."""
    return ssm.Person(np.array([x, y]), np.array([vx, vy]), radius, 2.0, 1)


def test_protective_separation_of_a_worked_example():
    """S_p of a floor scanner at 0.3 m and an arm at 3 m/s, computed by hand.

    v_h = 1.6 m/s, T_r = 0.12 s (0.08 scanner + 0.02 monitor + 0.02 bridge), the arm's
    joint at 2 rad/s braking at 6 rad/s^2: T_s = 2 / 6 = 1/3 s; uniform braking of the
    directed 3 m/s: S_s = 3 * (1/3) / 2 = 0.5 m; C = 1200 - 0.4 * 300 = 1080 mm;
    Z_d = 0.1 m, Z_r = 0.01 m.

        S_h = 1.6 * (0.12 + 0.333333) = 0.725333
        S_r = 3.0 * 0.12              = 0.36
        S_s                           = 0.5
        C + Z_d + Z_r = 1.08 + 0.11   = 1.19
        S_p                           = 2.775333 m
    """
    c = ssm.intrusion_distance(0.3)
    assert c == pytest.approx(1.08)
    s_p = ssm.protective_separation(1.6, 3.0, 0.12, 1.0 / 3.0, 0.5, c + 0.1 + 0.01)
    assert float(s_p) == pytest.approx(0.725333 + 0.36 + 0.5 + 1.19, abs=1e-6)
    assert float(s_p) == pytest.approx(2.775333, abs=1e-6)


def test_max_robot_speed_of_a_worked_example():
    """v_r,max at D = 2.0 m, computed by hand, and S_p at that speed is D.

    a = 3 m/s / (1/3 s) = 9 m/s^2, T_r = 0.12 s, v_h = 1.6 m/s, C' = 1.19 m:

        a T_r = 1.08,   a^2 T_r^2 = 1.1664,   v_h^2 = 2.56,   2 a (D - C') = 18 * 0.81 = 14.58
        v_r,max = -1.08 - 1.6 + sqrt(1.1664 + 2.56 + 14.58) = -2.68 + sqrt(18.3064)
                = -2.68 + 4.278598 = 1.598598 m/s

    At 1.598598 m/s: T_s = v / a = 0.177622 s, S_s = v^2 / 2a = 0.141973 m,
    S_h = 1.6 * (0.12 + 0.177622) = 0.476195, S_r = 1.598598 * 0.12 = 0.191832,
    S_p = 0.476195 + 0.191832 + 0.141973 + 1.19 = 2.000000 m.
    """
    v = float(ssm.max_robot_speed(2.0, 1.6, 9.0, 0.12, 1.19))
    assert v == pytest.approx(-2.68 + math.sqrt(18.3064), abs=1e-9)
    assert v == pytest.approx(1.598598, abs=1e-6)
    s_p = ssm.protective_separation(1.6, v, 0.12, v / 9.0, v * v / 18.0, 1.19)
    assert float(s_p) == pytest.approx(2.0, abs=1e-9)


@pytest.mark.parametrize('a, expected', [
    (3.0, [0.0, 0.29, 0.59, 1.11, 1.55, 1.95, 2.30]),
    (6.0, [0.0, 0.46, 0.93, 1.72, 2.38, 2.96, 3.48]),
])
def test_max_robot_speed_matches_the_research_notes_table(a, expected):
    """The notes' table (section 1.1): C' = 0.3 m, T_r = 0.15 s, v_h = 1.6 m/s."""
    d = [0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0]
    assert_allclose(ssm.max_robot_speed(d, 1.6, a, 0.15, 0.3), expected, atol=0.006)


@settings(max_examples=200, deadline=None)
@given(d=st.floats(0.0, 6.0), v_r=st.floats(0.01, 8.0), a=st.floats(0.5, 30.0),
       t_r=st.floats(0.0, 0.5), v_h=st.floats(0.0, 2.5), c=st.floats(0.0, 1.5))
def test_allowed_scale_is_the_closed_form_for_uniform_braking(d, v_r, a, t_r, v_h, c):
    """With S_s = v_r T_s / 2 and T_s = v_r / a, s v_r is the notes' v_r,max (capped at v_r)."""
    t_s = v_r / a
    s = float(ssm.allowed_scale(d, v_h, v_r, t_r, t_s, v_r * t_s / 2.0, c))
    v_max = float(ssm.max_robot_speed(d, v_h, a, t_r, c))
    assert 0.0 <= s <= 1.0
    assert s * v_r == pytest.approx(min(v_max, v_r), abs=1e-9 * max(1.0, v_r))


@settings(max_examples=200, deadline=None)
@given(d=st.floats(0.0, 6.0), v_r=st.floats(0.0, 8.0), t_s=st.floats(0.0, 0.5),
       s_s=st.floats(0.0, 2.0), t_r=st.floats(0.0, 0.5), v_h=st.floats(0.0, 2.5))
def test_allowed_scale_keeps_the_protective_separation(d, v_r, t_s, s_s, t_r, v_h):
    """At the allowed s, S_p(s) <= d; a little faster would break it (unless s = 1)."""
    c = 1.19
    s = float(ssm.allowed_scale(d, v_h, v_r, t_r, t_s, s_s, c))

    def s_p(x):
        return float(ssm.protective_separation(v_h, x * v_r, t_r, x * t_s, x * x * s_s, c))

    if s > 0.0:
        assert s_p(s) <= d + 1e-9
    else:
        assert s_p(0.0) >= d - 1e-12
    if 0.0 < s < 1.0:
        assert s_p(min(1.0, s + 1e-6)) > d - 1e-9


def test_intrusion_distance_follows_iso_13855():
    """C = 1200 - 0.4 H mm, at least 850 mm, for H in [0, 1000] mm."""
    assert ssm.intrusion_distance(0.0) == pytest.approx(1.2)
    assert ssm.intrusion_distance(0.875) == pytest.approx(0.85)
    assert ssm.intrusion_distance(1.0) == pytest.approx(0.85)
    with pytest.raises(ValueError, match='ISO 13855'):
        ssm.intrusion_distance(1.2)


def test_reach_speed_counts_only_for_short_distances():
    """ISO 13855: 2.0 m/s where the distance with it is <= 0.5 m, else 1.6 m/s."""
    assert_allclose(ssm.approach_speed(1.6, 2.0, 0.5, [0.3, 0.5, 0.51]), [2.0, 2.0, 1.6])


def test_params_from_config_sum_the_reaction_time(params):
    """T_r = scanner + monitor + bridge; C from the scan height; C' adds Z_d and Z_r."""
    cfg = load_config('people')
    assert params.reaction_time == pytest.approx(sum(cfg['monitor']['reaction'].values()))
    assert params.intrusion == pytest.approx(1.2 - 0.4 * cfg['scanner']['height'])
    assert params.constant == pytest.approx(params.intrusion + 0.1 + 0.01)


@settings(max_examples=30, deadline=None)
@given(q=st.tuples(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5), st.floats(0.0, 0.6)),
       qd=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-0.5, 0.5)))
def test_node_velocities_are_the_capsule_ends_time_derivatives(cell, q, qd):
    """Every capsule end's velocity matches the finite difference of the capsule model."""
    arm = cell.leader
    q, qd = np.array(q), np.array(qd)
    h = 1e-6
    s0, e0, _ = collision.arm_capsules(arm, q - h * qd)
    s1, e1, _ = collision.arm_capsules(arm, q + h * qd)
    v = ssm.node_velocities(arm, q, qd)
    ends = ssm._ENDS
    assert_allclose(v[ends[:, 0]], (s1 - s0) / (2 * h), atol=1e-6)
    assert_allclose(v[ends[:, 1]], (e1 - e0) / (2 * h), atol=1e-6)


def test_a_far_person_costs_nothing(cell, params):
    """A person 4 m beyond the reach leaves the arm at full speed, with the exact separation."""
    arm = cell.leader
    q = np.array([0.0, 0.0, 0.1])  # stretched along +x: the tool at x = 4.5
    r = ssm.assess_arm(arm, q, [2.0, 2.0, 0.5], [person(8.8, -2.0)], params)
    assert r.scale == 1.0 and r.relaxed == 1.0 and not r.stop and r.cause == ''
    start, end, radii = collision.arm_capsules(arm, q)
    column = collision.capsule_distance(start, end, radii, [8.8, -2.0, 0.0], [8.8, -2.0, 2.0],
                                        0.25)
    assert r.separation == pytest.approx(float(column.min()))
    assert r.margin > 0.0


def test_no_person_means_full_speed(cell, params):
    """Without a person the factor is 1 and the separation infinite."""
    r = ssm.assess_arm(cell.leader, np.zeros(3), np.ones(3), [], params)
    assert r.scale == 1.0 and r.separation == math.inf and not r.stop


def test_a_person_within_the_standstill_separation_stops_the_arm(cell, params):
    """S < v_h T_r + C' with the arm at rest: a protective stop, with the cause as text."""
    arm = cell.leader
    r = ssm.assess_arm(arm, [0.0, 0.0, 0.1], np.zeros(3), [person(5.5, -2.0)], params)
    assert r.separation < params.walking_speed * params.reaction_time + params.constant
    assert r.stop and r.scale == 0.0
    assert 'protective stop' in r.cause and 'scara_left' in r.cause and 'person 1' in r.cause


def test_moving_towards_the_person_allows_less_than_moving_away(cell, params):
    """The directed speed counts: the same swing towards the person is slowed more."""
    arm = cell.leader
    q = np.array([0.0, 0.0, 0.1])  # tool at (4.5, -2); the person to the tool's +y side
    p = [person(4.5, 0.9)]
    toward = ssm.assess_arm(arm, q, [2.0, 0.0, 0.0], p, params)   # swings towards +y
    away = ssm.assess_arm(arm, q, [-2.0, 0.0, 0.0], p, params)
    assert toward.scale < away.scale
    assert 'speed x' in toward.cause


def test_a_person_coming_closer_is_counted_by_its_measured_speed(cell, params):
    """A person tracked at 2.5 m/s towards the arm allows less than one standing."""
    arm = cell.leader
    q, qd = np.array([0.0, 0.0, 0.1]), np.array([1.0, 0.0, 0.0])
    still = ssm.assess_arm(arm, q, qd, [person(4.5, 0.3)], params)
    coming = ssm.assess_arm(arm, q, qd, [person(4.5, 0.3, vy=-2.5)], params)
    assert coming.margin < still.margin
    assert coming.scale < still.scale < 1.0


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(-math.pi, math.pi), d1=st.floats(2.8, 7.0), dd=st.floats(0.05, 2.0),
       q=st.tuples(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5), st.floats(0.0, 0.6)),
       qd=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-0.5, 0.5)))
def test_a_closer_person_never_allows_more(cell, params, angle, d1, dd, q, qd):
    """Along a ray from the shoulder, moving the person closer never raises the factor."""
    arm = cell.leader
    base = arm.base[:2, 3]
    u = np.array([math.cos(angle), math.sin(angle)])
    far = ssm.assess_arm(arm, q, qd, [person(*(base + (d1 + dd) * u))], params)
    near = ssm.assess_arm(arm, q, qd, [person(*(base + d1 * u))], params)
    assert near.scale <= far.scale + 1e-12


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(-math.pi, math.pi), dist=st.floats(2.6, 7.0),
       q=st.tuples(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5), st.floats(0.0, 0.6)),
       qd=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-0.5, 0.5)))
def test_running_at_the_allowed_factor_keeps_the_protective_separation(cell, params, angle,
                                                                       dist, q, qd):
    """At s times the planned velocity the margin S - S_p is not negative (rounding allowed).

    The stop scales exactly in joint space (time s, distance s^2); along the links' arcs the
    directed distance scales only nearly so, and the factor is checked where it slows to.
    """
    arm = cell.leader
    base = arm.base[:2, 3]
    p = [person(*(base + dist * np.array([math.cos(angle), math.sin(angle)])))]
    r = ssm.assess_arm(arm, q, qd, p, params)
    if r.scale > 0.0:
        scaled = ssm.assess_arm(arm, q, r.scale * np.array(qd), p, params)
        assert scaled.margin >= -1e-9


def test_an_overshooting_factor_is_lowered_until_the_margin_holds(cell, params, monkeypatch):
    """A pose where the quadratic's root leaves a 1.1 cm shortfall: the factor is lowered.

    Hypothesis found it (the shoulder swinging at 2 rad/s, a person 4 m away at 1 rad); the
    refined factor is below the root, and at it the margin is not negative.
    """
    arm = cell.leader
    base = arm.base[:2, 3]
    p = [person(*(base + 4.0 * np.array([math.cos(1.0), math.sin(1.0)])))]
    q, qd = np.zeros(3), np.array([2.0, 0.0, 0.0])
    refined = ssm.assess_arm(arm, q, qd, p, params)
    monkeypatch.setattr(ssm, 'REFINE_STEPS', 0)
    root = ssm.assess_arm(arm, q, qd, p, params)
    assert ssm.assess_arm(arm, q, root.scale * qd, p, params).margin < -0.005
    monkeypatch.undo()
    assert 0.0 < refined.scale < root.scale
    assert ssm.assess_arm(arm, q, refined.scale * qd, p, params).margin >= 0.0
    assert f'speed x {refined.scale:.2f}' in refined.cause


def test_the_stopping_distance_covers_braking(cell, params):
    """S_p counts at least the braking distance towards the person (compared to rest)."""
    arm = cell.leader
    q, qd = np.array([0.0, 0.0, 0.1]), np.array([2.0, 0.0, 0.0])
    p = [person(4.5, 2.0)]
    moving = ssm.assess_arm(arm, q, qd, p, params)
    resting = ssm.assess_arm(arm, q, np.zeros(3), p, params)
    t_s = safety.stopping_time(arm, qd)
    tool_speed = 2.0 * 2.5  # the tool swings towards +y at 5 m/s
    # margin drop: v_h T_s + v_r T_r + S_s, with S_s at least the uniform-braking distance
    drop = resting.margin - moving.margin
    assert drop >= params.walking_speed * t_s + tool_speed * params.reaction_time \
        + tool_speed * t_s / 2.0 - 0.05


def test_braking_rate_is_one_over_the_stopping_time(cell):
    """The factor may fall at 1 / T_s: 3 /s at full revolute speed, inf at rest."""
    arm = cell.leader
    assert ssm.braking_rate(arm, [2.0, -1.0, 0.0]) == pytest.approx(3.0)
    assert ssm.braking_rate(arm, [0.0, 0.0, 0.5]) == pytest.approx(4.0)
    assert ssm.braking_rate(arm, np.zeros(3)) == math.inf
