"""Collision geometry: segment distance against brute force and coal, capsule arms, delays."""
import dataclasses

import coal
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core import kinematics
from scara_collab.core.collision import (arm_capsules, arm_distance, arm_pair_distances,
                                         capsule_distance, closest_points, first_safe_delay,
                                         paths_apart, segment_distance, smallest_safe_delay,
                                         trajectory_min_distance)
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import interp_rows

BELT_POINT = (2.0, 0.0)


def brute_distance(p0, p1, q0, q1, n=801):
    """Min distance over n x n samples of both segments, and its sampling error bound."""
    u = np.linspace(0.0, 1.0, n)[:, None]
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    ps = p0 + u * (p1 - p0)
    qs = q0 + u * (q1 - q0)
    d = np.sqrt(((ps[:, None, :] - qs[None, :, :]) ** 2).sum(-1)).min()
    bound = (np.linalg.norm(p1 - p0) + np.linalg.norm(q1 - q0)) / (2 * (n - 1))
    return d, bound


def point_segment(p, a, b):
    """Return the distance of point ``p`` from the segment ``a``-``b`` (test-local)."""
    ab = b - a
    denom = ab @ ab
    u = 0.0 if denom == 0.0 else np.clip((p - a) @ ab / denom, 0.0, 1.0)
    return np.linalg.norm(p - (a + u * ab))


def endpoint_only_distance(p0, p1, q0, q1):
    """Return the design documents' check: 4 endpoint-to-segment distances (misses crossings)."""
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    return min(point_segment(p0, q0, q1), point_segment(p1, q0, q1),
               point_segment(q0, p0, p1), point_segment(q1, p0, p1))


CASES = {
    # name: (p0, p1, q0, q1, exact distance)
    'crossing_in_plane': ((0, 0, 0), (1, 1, 0), (0, 1, 0), (1, 0, 0), 0.0),
    'skew_crossing_at_height': ((0, 0, 0), (1, 1, 0), (0, 1, 0.3), (1, 0, 0.3), 0.3),
    'crossing_off_centre': ((0, 0, 0), (4, 0, 0), (1, -1, 0.2), (1, 3, 0.2), 0.2),
    't_junction': ((0, 0, 0), (2, 0, 0), (1, 0, 0), (1, 1, 0), 0.0),
    'parallel_overlapping': ((0, 0, 0), (1, 0, 0), (0.5, 0.2, 0), (1.5, 0.2, 0), 0.2),
    'parallel_disjoint': ((0, 0, 0), (1, 0, 0), (2, 1, 0), (3, 1, 0), np.sqrt(2.0)),
    'antiparallel_disjoint': ((0, 0, 0), (1, 0, 0), (3, 0, 1), (2, 0, 1), np.sqrt(2.0)),
    'collinear_overlapping': ((0, 0, 0), (2, 0, 0), (1, 0, 0), (3, 0, 0), 0.0),
    'collinear_contained': ((0, 0, 0), (3, 0, 0), (2, 0, 0), (1, 0, 0), 0.0),
    'collinear_disjoint': ((0, 0, 0), (1, 0, 0), (1.5, 0, 0), (3, 0, 0), 0.5),
    'collinear_disjoint_reversed': ((0, 0, 0), (1, 0, 0), (3, 0, 0), (1.5, 0, 0), 0.5),
    'nearly_parallel': ((0, 0, 0), (1, 0, 0), (0, 0.1, 0), (1, 0.1 + 1e-9, 0), 0.1),
    # Below the angle where a e - b^2 is rounding noise: a Gram-determinant parallel test
    # calls these parallel, takes s = 0 and is off by ~1e-7.
    'nearly_parallel_crossing': ((0, 0, 0), (1, 0, 0), (0, -1e-7, 0), (1, 1e-7, 0), 0.0),
    'nearly_parallel_touching': ((6e-8, 6e-8, 6e-8), (1, 0, 0), (1, 0, 0), (0, 0, 0), 0.0),
    'point_vs_segment_interior': ((0.5, 1, 0), (0.5, 1, 0), (0, 0, 0), (1, 0, 0), 1.0),
    'segment_vs_point_beyond_end': ((0, 0, 0), (1, 0, 0), (2, 0, 0), (2, 0, 0), 1.0),
    'point_vs_point': ((0, 0, 0), (0, 0, 0), (1, 2, 2), (1, 2, 2), 3.0),
    'endpoints_touching': ((0, 0, 0), (1, 0, 0), (1, 0, 0), (1, 5, 7), 0.0),
}


@pytest.mark.parametrize('name', sorted(CASES))
def test_segment_distance_known_cases_and_brute_force(name):
    """Each known case gives its exact distance and no more than brute force.

    The closest points lie on the segments and are the distance apart.
    """
    p0, p1, q0, q1, expected = CASES[name]
    d, s, t = segment_distance(p0, p1, q0, q1)
    assert d.shape == () and s.shape == () and t.shape == ()
    assert d == pytest.approx(expected, abs=1e-12)
    assert 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0
    cp = np.add(p0, s * np.subtract(p1, p0))
    cq = np.add(q0, t * np.subtract(q1, q0))
    assert np.linalg.norm(cp - cq) == pytest.approx(float(d), abs=1e-12)
    brute, bound = brute_distance(p0, p1, q0, q1)
    assert d <= brute + 1e-12
    assert brute - d <= bound + 1e-12


def test_crossing_segments_are_what_the_design_documents_check_missed():
    """Two crossing diagonals touch at their midpoints; the documents' endpoint check: 0.71 m."""
    p0, p1, q0, q1 = (0, 0, 0), (1, 1, 0), (0, 1, 0), (1, 0, 0)
    d, s, t = segment_distance(p0, p1, q0, q1)
    assert float(d) == 0.0 and (float(s), float(t)) == (0.5, 0.5)
    assert endpoint_only_distance(p0, p1, q0, q1) == pytest.approx(np.sqrt(0.5))


def test_segment_distance_random_pairs_against_brute_force():
    """Random segment pairs, many coplanar, agree with brute-force sampling within its bound."""
    rng = np.random.default_rng(7)
    for _ in range(40):
        p0, p1, q0, q1 = rng.uniform(-1.0, 1.0, (4, 3))
        if rng.uniform() < 0.3:  # flatten into one plane: crossings become likely
            p0[2] = p1[2] = q0[2] = q1[2] = 0.0
        d, _, _ = segment_distance(p0, p1, q0, q1)
        brute, bound = brute_distance(p0, p1, q0, q1, n=601)
        assert d <= brute + 1e-12
        assert brute - d <= bound + 1e-12


def test_segment_distance_broadcasts_and_matches_single_calls():
    """Broadcast segment arrays give, element by element, the results of single calls."""
    rng = np.random.default_rng(1)
    p0 = rng.normal(size=(5, 1, 3))
    p1 = rng.normal(size=(5, 1, 3))
    q0 = rng.normal(size=(1, 4, 3))
    q1 = rng.normal(size=(3,))
    d, s, t = segment_distance(p0, p1, q0, q1)
    assert d.shape == s.shape == t.shape == (5, 4)
    for i in range(5):
        for j in range(4):
            dij, sij, tij = segment_distance(p0[i, 0], p1[i, 0], q0[0, j], q1)
            assert_allclose([d[i, j], s[i, j], t[i, j]], [dij, sij, tij], rtol=0, atol=1e-15)


def _coal_capsule(p0, p1, radius):
    """Return a coal capsule and pose with axis p0-p1 (a coal capsule's axis is its local z)."""
    axis = p1 - p0
    length = np.linalg.norm(axis)
    z = axis / length
    helper = np.eye(3)[np.argmin(np.abs(z))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    rot = np.column_stack([x, np.cross(z, x), z])
    return coal.Capsule(radius, length), coal.Transform3s(rot, (p0 + p1) / 2)


def coal_capsule_distance(p0, p1, rp, q0, q1, rq):
    """Return the surface distance of two capsules as coal computes it."""
    cap_p, tf_p = _coal_capsule(p0, p1, rp)
    cap_q, tf_q = _coal_capsule(q0, q1, rq)
    return coal.distance(cap_p, tf_p, cap_q, tf_q, coal.DistanceRequest(), coal.DistanceResult())


def test_capsule_distance_matches_coal():
    """The capsule surface distance agrees with coal to 1e-6 m on 500 separate pairs."""
    rng = np.random.default_rng(11)
    errors = []
    while len(errors) < 500:
        p0, p1, q0, q1 = rng.uniform(-1.0, 1.0, (4, 3))
        if len(errors) % 3 == 0:  # nearly coplanar pairs, often crossing in plan view
            p0[2], p1[2], q0[2], q1[2] = 0.0, 0.0, 0.15, 0.15
        rp, rq = rng.uniform(0.01, 0.1, 2)
        ours = float(capsule_distance(p0, p1, rp, q0, q1, rq))
        if ours < 1e-3:  # coal's penetration depth is a different quantity: compare apart only
            continue
        errors.append(abs(ours - coal_capsule_distance(p0, p1, rp, q0, q1, rq)))
    assert max(errors) < 1e-6


coords = arrays(np.float64, (3,), elements=st.floats(-10.0, 10.0, allow_nan=False))
unit = st.floats(0.0, 1.0)


@settings(max_examples=300, deadline=None)
@given(coords, coords, coords, coords, unit, unit)
def test_segment_distance_properties(p0, p1, q0, q1, u, v):
    """The distance is symmetric and blind to segment direction (hypothesis).

    Its closest points achieve it, and no other pair of points does better.
    """
    d, s, t = segment_distance(p0, p1, q0, q1)
    assert d >= 0.0 and 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0
    tol = 1e-10 * (1.0 + np.abs([p0, p1, q0, q1]).max())
    # Symmetric, and blind to the direction of either segment.
    assert segment_distance(q0, q1, p0, p1)[0] == pytest.approx(float(d), abs=tol)
    assert segment_distance(p1, p0, q0, q1)[0] == pytest.approx(float(d), abs=tol)
    assert segment_distance(p0, p1, q1, q0)[0] == pytest.approx(float(d), abs=tol)
    # The closest points achieve the distance, and no other pair of points does better.
    cp, cq = p0 + s * (p1 - p0), q0 + t * (q1 - q0)
    assert np.linalg.norm(cp - cq) == pytest.approx(float(d), abs=tol)
    assert d <= np.linalg.norm(p0 + u * (p1 - p0) - q0 - v * (q1 - q0)) + tol
    assert d <= endpoint_only_distance(p0, p1, q0, q1) + tol


def planar_ik(arm, xy, elbow=1.0):
    """Joint angles putting the quill axis of arm over world point xy (test-local IK)."""
    dx, dy = np.asarray(xy, dtype=float) - arm.base_position[:2]
    c2 = (dx * dx + dy * dy - arm.l1 ** 2 - arm.l2 ** 2) / (2 * arm.l1 * arm.l2)
    t2 = elbow * np.arccos(c2)
    t1 = np.arctan2(dy, dx) - np.arctan2(arm.l2 * np.sin(t2), arm.l1 + arm.l2 * np.cos(t2))
    return np.array([t1, t2])


@pytest.fixture(scope='module')
def arms():
    """Return the cell's leader and follower."""
    cell = load_cell()
    return cell.leader, cell.follower


def test_arm_capsules_geometry_with_translated_and_rotated_base(arms):
    """Capsule ends sit where the link lengths and heights put them, also on a turned base."""
    left, _ = arms
    start, end, radii = arm_capsules(left, [0.0, 0.0, 0.25])
    bx, by, bz = left.base_position
    h1 = bz + left.shoulder_height
    h2 = h1 + left.elbow_rise
    tool = (bx + left.l1 + left.l2, by)
    assert_allclose(start, [[bx, by, h1], [bx + left.l1, by, h2], [*tool, h2 - 0.25]])
    top = h2 - 0.25 + left.quill_length
    assert_allclose(end, [[bx + left.l1, by, h1], [*tool, h2], [*tool, top]])
    assert_allclose(radii, [left.link_radius, left.link_radius, left.quill_radius])
    # A base turned 90 deg about z: theta1 = 0 now points link 1 along world +y.
    base = np.array(left.base)
    base[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    turned = dataclasses.replace(left, base=base)
    start, end, _ = arm_capsules(turned, [np.pi / 2, 0.0, 0.0])
    assert_allclose(end[0], [bx - left.l1, by, h1], atol=1e-12)
    assert_allclose(end[1], [bx - left.l1 - left.l2, by, h2], atol=1e-12)


def test_arm_capsules_agree_with_kinematics(arms):
    """The capsule axes start at the kinematics' tool tip, shoulder and elbow."""
    rng = np.random.default_rng(5)
    for arm in arms:
        q = rng.uniform(arm.lower, arm.upper, (100, 3))
        start, end, _ = arm_capsules(arm, q)
        assert_allclose(start[:, 2], kinematics.fk(arm, q), atol=1e-12)
        points = kinematics.arm_points(arm, q)
        assert_allclose(start[:, 0], points[:, 0], atol=1e-12)
        assert_allclose(end[:, 0], points[:, 1], atol=1e-12)


def test_arms_at_home_are_far_apart(arms):
    """At home the nearest capsules are the two link 1s, the base gap less two radii apart."""
    left, right = arms
    d = arm_distance(left, [-np.pi / 2, 0.0, 0.0], right, [np.pi / 2, 0.0, 0.0])
    # Nearest: the two link 1 capsules at the shoulders, 4 m apart at the same height.
    gap = right.base_position[1] - left.base_position[1]
    assert float(d) == pytest.approx(gap - 2 * left.link_radius)
    assert d > 3.0


def test_arms_reaching_the_same_belt_point_overlap(arms):
    """Both arms at the same belt point overlap by two link radii, for either elbow."""
    left, right = arms
    for elbow in (1.0, -1.0):
        q_left = np.r_[planar_ik(left, BELT_POINT, elbow), 0.3]
        q_right = np.r_[planar_ik(right, BELT_POINT, -elbow), 0.3]
        start_l, _, _ = arm_capsules(left, q_left)
        assert_allclose(start_l[2, :2], BELT_POINT, atol=1e-12)
        # Link 2 ends coincide at the same height: overlap of two link radii.
        d = arm_distance(left, q_left, right, q_right)
        assert float(d) == pytest.approx(-2 * left.link_radius, abs=1e-9)
        pairs = arm_pair_distances(left, q_left, right, q_right)
        assert pairs.shape == (3, 3) and pairs[2, 2] == pytest.approx(-2 * left.quill_radius)


@pytest.mark.parametrize('profile', ['slim', 'default', 'heavy'])
def test_link_1_crossing_link_2_in_plan_view_is_detected(profile):
    """Link 1 crossing link 2 in plan view breaks the margin, in every profile.

    The design documents' endpoint-only check calls the same poses safe.
    """
    cell = load_cell(profile)
    left, right = cell.leader, cell.follower
    # In the real cell the follower's link 2 cannot reach over the leader's link 1, so the
    # follower is bolted down nearer: base (2.5, 0.5). Left link 1 runs from (2, -2) to
    # (2, -0.5) at z 0.6; right link 2 from (2.5, -1) to (1.5, -1) at z 0.7: crossing at (2, -1).
    base = np.array(right.base)
    base[:2, 3] = 2.5, 0.5
    near = dataclasses.replace(right, base=base)
    q_left = [np.pi / 2, np.pi / 2, 0.0]
    q_right = [-np.pi / 2, -np.pi / 2, 0.0]
    pairs = arm_pair_distances(left, q_left, near, q_right)
    expected = left.elbow_rise - 2 * left.link_radius  # 0.05 / 0.0 / -0.05
    assert pairs[0, 1] == pytest.approx(expected, abs=1e-12)
    assert float(arm_distance(left, q_left, near, q_right)) == pytest.approx(expected, abs=1e-12)
    assert arm_distance(left, q_left, near, q_right) < cell.safety_margin
    start_l, end_l, _ = arm_capsules(left, q_left)
    start_r, end_r, _ = arm_capsules(near, q_right)
    theirs = endpoint_only_distance(start_l[0], end_l[0], start_r[1], end_r[1])
    assert theirs - 2 * left.link_radius > 3 * cell.safety_margin  # their check says safe


def test_arm_distance_vectorised_and_symmetric(arms):
    """N state pairs give N single calls' distances, symmetric in the arms, and broadcast."""
    left, right = arms
    rng = np.random.default_rng(2)
    q_l = rng.uniform(left.lower, left.upper, (200, 3))
    q_r = rng.uniform(right.lower, right.upper, (200, 3))
    d = arm_distance(left, q_l, right, q_r)
    assert d.shape == (200,)
    singles = [float(arm_distance(left, a, right, b)) for a, b in zip(q_l, q_r)]
    assert_allclose(d, singles, rtol=0, atol=1e-15)
    assert_allclose(arm_distance(right, q_r, left, q_l), d, rtol=0, atol=1e-12)
    assert arm_distance(left, q_l, right, q_r[0]).shape == (200,)  # one b state against N a's
    assert arm_pair_distances(left, q_l, right, q_r).shape == (200, 3, 3)


def joint_path(waypoints):
    """Time-stamped joint trajectory through (time, theta1, theta2, d3) waypoints, 0.1 s apart."""
    waypoints = np.asarray(waypoints, dtype=float)
    t = np.arange(waypoints[0, 0], waypoints[-1, 0] + 1e-9, 0.1)
    return t, interp_rows(t, waypoints[:, 0], waypoints[:, 1:])


def hold_interp(t, ts, qs):
    """Scalar linear interpolation with held ends (independent of numpy.interp)."""
    if t <= ts[0]:
        return qs[0]
    if t >= ts[-1]:
        return qs[-1]
    i = int(np.nonzero(ts <= t)[0][-1])
    w = (t - ts[i]) / (ts[i + 1] - ts[i])
    return (1 - w) * qs[i] + w * qs[i + 1]


def brute_min(left, t_a, q_a, right, t_b, q_b, start_b, dt=0.002):
    """Return the smallest distance and its time by stepping both held trajectories by ``dt``."""
    t_b = t_b + start_b
    best = (np.inf, None)
    for t in np.arange(min(t_a[0], t_b[0]), max(t_a[-1], t_b[-1]) + dt, dt):
        d = float(arm_distance(left, hold_interp(t, t_a, q_a), right, hold_interp(t, t_b, q_b)))
        best = min(best, (d, t), key=lambda x: x[0])
    return best


@pytest.fixture(scope='module')
def belt_scenario(arms):
    """Left visits the belt point over t 1.5-3.5; right wants to be there over t 1.5-3.0."""
    left, right = arms
    home_l, home_r = [-np.pi / 2, 0.5, 0.0], [np.pi / 2, -0.5, 0.0]
    at_l = [*planar_ik(left, BELT_POINT), 0.4]
    at_r = [*planar_ik(right, BELT_POINT, -1.0), 0.4]
    t_a, q_a = joint_path([[0.0, *home_l], [1.5, *at_l], [2.5, *at_l], [4.0, *home_l]])
    t_b, q_b = joint_path([[0.0, *home_r], [1.5, *at_r], [2.0, *at_r], [3.5, *home_r]])
    return t_a, q_a, t_b, q_b


def test_trajectory_min_distance_against_brute_loop(arms, belt_scenario):
    """The trajectory minimum matches a brute-force time loop for several start delays.

    Started after the leader is home again, the follower's whole path is checked against
    that pose.
    """
    left, right = arms
    t_a, q_a, t_b, q_b = belt_scenario
    # Joint speeds here are below 2 rad/s: a point moves < 2 * 2.6 m/s, two arms < 11 m/s.
    tol = 11.0 * (0.005 + 0.002) / 2
    for start_b in (0.0, 1.3, 2.7, 6.0):
        d, t_min = trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=start_b)
        d_ref, t_ref = brute_min(left, t_a, q_a, right, t_b, q_b, start_b)
        assert d == pytest.approx(d_ref, abs=tol)
        at_min = arm_distance(left, hold_interp(t_min, t_a, q_a), right,
                              hold_interp(t_min, t_b + start_b, q_b))
        assert float(at_min) == pytest.approx(d, abs=1e-12)
    # Right starting after left is home again: right's whole path against left's home pose
    # (sampled finer than right's stamps, so at most the stamps' minimum).
    d, t_min = trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=6.0)
    alone = arm_distance(left, q_a[-1], right, q_b)
    assert alone.min() - tol <= d <= alone.min() + 1e-12
    assert t_min >= 6.0


def test_trajectory_min_distance_holds_ends_and_rejects_bad_input(arms):
    """One-point trajectories are held poses; bad times, lengths and NaN are refused."""
    left, right = arms
    q_l, q_r = np.array([[-1.0, 0.2, 0.0]]), np.array([[1.0, -0.2, 0.1]])
    d, t = trajectory_min_distance(left, [0.0], q_l, right, [0.0], q_r, start_b=2.0)
    assert d == pytest.approx(float(arm_distance(left, q_l[0], right, q_r[0])))
    with pytest.raises(ValueError):
        trajectory_min_distance(left, [0.0, 0.0], np.zeros((2, 3)), right, [0.0], q_r)
    with pytest.raises(ValueError):
        trajectory_min_distance(left, [0.0, 1.0], np.zeros((3, 3)), right, [0.0], q_r)
    with pytest.raises(ValueError):
        trajectory_min_distance(left, [0.0], [[np.nan, 0, 0]], right, [0.0], q_r)


def test_smallest_safe_delay_is_safe_and_tight(arms, belt_scenario):
    """The delay found keeps the margin, one resolution step less does not."""
    left, right = arms
    t_a, q_a, t_b, q_b = belt_scenario
    margin = load_cell().safety_margin
    resolution = 0.01
    assert trajectory_min_distance(left, t_a, q_a, right, t_b, q_b)[0] < margin
    delay = smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, margin, resolution=resolution)
    assert delay is not None and delay > 0.0
    assert trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=delay)[0] >= margin
    before = trajectory_min_distance(left, t_a, q_a, right, t_b, q_b,
                                     start_b=delay - resolution)[0]
    assert before < margin
    assert delay == pytest.approx(round(delay / resolution) * resolution)


def test_smallest_safe_delay_zero_when_already_safe(arms, belt_scenario):
    """Trajectories that never come near need no delay."""
    left, right = arms
    t_a, q_a, _, _ = belt_scenario
    t_b, q_b = joint_path([[0.0, np.pi / 2, 0.0, 0.0], [2.0, 2.0, -0.5, 0.3]])
    assert smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, 0.10) == 0.0


def test_smallest_safe_delay_none_when_impossible(arms, belt_scenario):
    """No delay is found when none can help, or the one needed exceeds ``max_delay``.

    The follower waits next to the working leader, or ends next to where the leader ends.
    """
    left, right = arms
    t_a, q_a, t_b, q_b = belt_scenario
    margin = 0.10
    # Left works on the belt point (quill down and up); right starts, and so waits, next to it.
    at_l = planar_ik(left, BELT_POINT)
    t_park, q_park = joint_path([[0.0, *at_l, 0.0], [1.0, *at_l, 0.4], [2.0, *at_l, 0.0]])
    q_near = [*planar_ik(right, (2.0, 0.15), -1.0), 0.0]
    t_near, q_near = joint_path([[0.0, *q_near], [1.0, np.pi / 2, 0.0, 0.0]])
    assert smallest_safe_delay(left, t_park, q_park, right, t_near, q_near, margin) is None
    # Right ends next to where left ends: no delay can help (decided from the final poses).
    t_end, q_end = joint_path([[0.0, np.pi / 2, 0.0, 0.0], [1.0, *q_near[0]]])
    assert smallest_safe_delay(left, t_park, q_park, right, t_end, q_end, margin) is None
    # A delay exists for the belt scenario, but not within a too-short max_delay.
    assert smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, margin, max_delay=0.5) is None


def test_smallest_safe_delay_stops_searching_once_the_leader_has_ended(
        arms, belt_scenario, monkeypatch):
    """A follower whose waiting pose blocks the leader is refused after a few checks.

    Beyond the delay at which the follower starts after the leader's end, every delay is the
    same check (leader moves, follower waits; then the follower moves alone); the search
    stops at the first such delay instead of scanning up to ``max_delay`` (121 checks).
    """
    from scara_collab.core import collision
    left, right = arms
    at_l = planar_ik(left, BELT_POINT)
    t_park, q_park = joint_path([[0.0, *at_l, 0.0], [1.0, *at_l, 0.4], [2.0, *at_l, 0.0]])
    q_near = [*planar_ik(right, (2.0, 0.15), -1.0), 0.0]
    t_near, q_near = joint_path([[0.0, *q_near], [1.0, np.pi / 2, 0.0, 0.0]])
    checks = []
    grid_safe = collision._grid_safe
    monkeypatch.setattr(collision, '_grid_safe', lambda *a: checks.append(1) or grid_safe(*a))
    assert smallest_safe_delay(left, t_park, q_park, right, t_near, q_near, 0.10,
                               max_delay=30.0) is None
    assert 1 <= len(checks) <= 2.0 / 0.25 + 2, len(checks)  # scan points up to the leader's end
    # a delay that exists is the one the plain search over every delay finds
    t_a, q_a, t_b, q_b = belt_scenario
    plain = collision.first_safe_delay(lambda k: trajectory_min_distance(
        left, t_a, q_a, right, t_b, q_b, start_b=k * 0.01)[0] >= 0.10, 30.0)
    assert smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, 0.10) == plain > 0.0


def test_smallest_safe_delay_when_safety_is_not_monotonic(arms):
    """With two leader visits the first safe window is found, although later ones are not."""
    left, right = arms
    margin = 0.10
    home_l, home_r = [-np.pi / 2, 0.5, 0.0], [np.pi / 2, -0.5, 0.0]
    at_l = [*planar_ik(left, BELT_POINT), 0.0]
    at_r = [*planar_ik(right, BELT_POINT, -1.0), 0.0]
    # Left visits the belt point twice with a long gap; right pops in and out quickly.
    t_a, q_a = joint_path([[0.0, *home_l], [1.0, *at_l], [1.5, *at_l], [2.5, *home_l],
                           [7.0, *home_l], [8.0, *at_l], [8.5, *at_l], [9.5, *home_l]])
    t_b, q_b = joint_path([[0.0, *home_r], [1.0, *at_r], [2.0, *home_r]])
    delay = smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, margin)
    # The first window (between left's visits) is found, not the one after left's second.
    assert delay is not None and 0.0 < delay < 6.0
    assert trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=delay)[0] >= margin
    # ... although a later delay, inside left's second visit, is unsafe again.
    assert trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=7.25)[0] < margin


def test_first_safe_delay_scans_then_bisects():
    """The delay is the first safe step after the last unsafe one before the first safe scan.

    Against a plain loop over every step, for safe sets with islands the scan may miss.
    """
    rng = np.random.default_rng(2)
    for case in range(200):
        safe_steps = rng.uniform(size=301) < rng.uniform(0.0, 0.3)
        calls = []

        def safe(k):
            calls.append(k)
            return bool(safe_steps[k])

        got = first_safe_delay(safe, max_delay=3.0, resolution=0.01, scan_step=0.25)
        scan = [*range(0, 301, 25)]
        hits = [k for k in scan if safe_steps[k]]
        if not hits:
            assert got is None, case
            continue
        k = round(got / 0.01)
        assert got == k * 0.01 and safe_steps[k] and k <= hits[0], case
        assert k == 0 or (not safe_steps[k - 1] and k - 1 >= max(0, hits[0] - 25)), case
        assert len(calls) <= len(scan) + 6, case  # 25 steps bisected in at most 5, + 1 check
    assert first_safe_delay(lambda k: k >= 37, max_delay=2.0) == 0.37
    assert first_safe_delay(lambda k: True, max_delay=0.0) == 0.0
    with pytest.raises(ValueError, match='resolution'):
        first_safe_delay(lambda k: True, 1.0, resolution=0.0)
    with pytest.raises(ValueError, match='max_delay'):
        first_safe_delay(lambda k: True, -1.0)


def test_closest_points_are_on_the_closest_capsule_axes(cell):
    """The closest points lie on the closest capsule pair's axes, the distance apart."""
    left, right = cell.arms
    rng = np.random.default_rng(4)
    for _ in range(20):
        q_l = rng.uniform(left.lower, left.upper)
        q_r = rng.uniform(right.lower, right.upper)
        pairs, d, p, q = closest_points(left, q_l, right, q_r)
        assert_allclose(pairs, arm_pair_distances(left, q_l, right, q_r))
        assert d == pytest.approx(float(arm_distance(left, q_l, right, q_r)), abs=1e-12)
        i, j = np.unravel_index(int(np.argmin(pairs)), pairs.shape)
        radii = arm_capsules(left, q_l)[2][i] + arm_capsules(right, q_r)[2][j]
        assert np.linalg.norm(p - q) - radii == pytest.approx(d, abs=1e-9)


SEGMENT_CASES = [  # crossing, parallel, collinear apart and overlapping, points, touching
    ((0, 0, 0), (1, 1, 0), (0, 1, 0), (1, 0, 0)),
    ((0, 0, 0), (2, 0, 0), (0, 1, 0), (2, 1, 0)),
    ((0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)),
    ((0, 0, 0), (2, 0, 0), (1, 0, 0), (3, 0, 0)),
    ((0, 0, 0), (0, 0, 0), (1, -1, 1), (1, 1, 1)),
    ((0, 0, 0), (1, 0, 0), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5)),
    ((1, 1, 1), (1, 1, 1), (1, 1, 1), (1, 1, 1)),
    ((0, 0, 0), (1, 0, 0), (1, 0, 0), (1, 1, 0)),
    ((0, 0, 0), (1, 0, 0), (1, 1e-9, 0), (-1, 1e-9, 1e-12)),
]


@pytest.mark.parametrize('p0, p1, q0, q1', SEGMENT_CASES)
def test_one_segment_pair_is_the_batch_formula(p0, p1, q0, q1):
    """One pair (plain floats) gives the batch's (arrays) distance and parameters, bit for bit.

    Special cases included: points, parallel and collinear segments.
    """
    one = segment_distance(p0, p1, q0, q1)
    many = segment_distance(*(np.array([v, v]) for v in (p0, p1, q0, q1)))
    assert all(x.shape == () for x in one)
    assert np.array_equal(np.array(one), np.array(many)[:, 0])


@settings(max_examples=300, deadline=None)
@given(arrays(float, (4, 3), elements=st.floats(-3, 3)), st.integers(0, 3))
def test_one_segment_pair_is_the_batch_formula_on_random_segments(pts, degenerate):
    """Random segments, with one made a point or the two made parallel now and then."""
    p0, p1, q0, q1 = pts
    if degenerate == 1:
        p1 = p0
    elif degenerate == 2:
        q1 = q0 + 0.7 * (p1 - p0)
    one = segment_distance(p0, p1, q0, q1)
    many = segment_distance(*(np.array([v]) for v in (p0, p1, q0, q1)))
    assert np.array_equal(np.array(one), np.array(many)[:, 0])


def test_one_state_pair_is_the_batch_formula(cell):
    """arm_pair_distances of one state pair (plain floats) equals the batch's, bit for bit."""
    left, right = cell.arms
    rng = np.random.default_rng(11)
    q_l = np.vstack([rng.uniform(left.lower, left.upper, (500, 3)), np.zeros(3),
                     [0.0, 0.0, left.upper[2]]])
    q_r = np.vstack([rng.uniform(right.lower, right.upper, (500, 3)), np.zeros(3), np.zeros(3)])
    batch = arm_pair_distances(left, q_l, right, q_r)
    for k in range(len(q_l)):
        one = arm_pair_distances(left, q_l[k], right, q_r[k])
        assert one.shape == (3, 3)
        assert np.array_equal(one, batch[k])


def test_paths_apart_at_any_timing_against_the_timed_distance(arms):
    """Apart at any timing: every state of one path against every state of the other.

    Two lines that cross the belt's centre at different times keep the margin when timed (one
    waits for the other) but not at every timing: not apart. Lines on their own halves are.
    """
    left, right = arms
    to_centre = np.linspace(kinematics.ik(left, [3.0, -1.2, 0.4]).q,
                            kinematics.ik(left, [3.0, 0.0, 0.4]).q, 40)
    back = to_centre[::-1]
    left_path = np.vstack([to_centre, back])
    right_path = np.linspace(kinematics.ik(right, [3.0, 1.2, 0.4]).q,
                             kinematics.ik(right, [3.0, 0.05, 0.4]).q, 40)
    t_left = np.linspace(0.0, 2.0, 80)
    t_right = np.linspace(0.0, 1.0, 40)
    # timed: the right arm comes in after the left one has left
    timed, _ = trajectory_min_distance(left, t_left, left_path, right, t_right, right_path,
                                       start_b=2.5)
    assert timed > 0.1
    assert not paths_apart(left, left_path, right, right_path, 0.1)
    own_half = np.linspace(kinematics.ik(right, [3.0, 1.2, 0.4]).q,
                           kinematics.ik(right, [2.2, 0.8, 0.4]).q, 40)
    assert paths_apart(left, to_centre[:20], right, own_half, 0.1)
    # the sampling never hides a meeting: against every pair of the dense paths
    dense = arm_distance(left, np.repeat(to_centre[:20], 40, axis=0),
                         right, np.tile(own_half, (20, 1)))
    assert dense.min() > 0.1
