"""The conflict check's prefilter: same results as the full computation, bit for bit."""
import dataclasses

import numpy as np
import pytest

from scara_collab.core import collision
from scara_collab.core.collision import (arm_distance, arm_pair_distances, first_safe_delay,
                                         smallest_safe_delay, trajectory_min_distance)
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import interp_rows

MARGIN = 0.10


@pytest.fixture(scope='module')
def arms():
    """Return the cell's leader and follower (and check the cell's margin is the test's)."""
    cell = load_cell()
    assert cell.safety_margin == pytest.approx(MARGIN)
    return cell.leader, cell.follower


def planar_ik(arm, xy, elbow):
    """Joint angles putting the quill axis of ``arm`` over world point ``xy`` (test-local IK)."""
    dx, dy = np.asarray(xy, dtype=float) - arm.base_position[:2]
    c2 = (dx * dx + dy * dy - arm.l1 ** 2 - arm.l2 ** 2) / (2 * arm.l1 * arm.l2)
    t2 = elbow * np.arccos(np.clip(c2, -1.0, 1.0))
    t1 = np.arctan2(dy, dx) - np.arctan2(arm.l2 * np.sin(t2), arm.l1 + arm.l2 * np.cos(t2))
    return np.array([t1, t2])


def random_pose(rng, arm, elbow, y_range):
    """Return a joint state with the tool over a random point of the strip ``y_range``."""
    while True:
        xy = (rng.uniform(0.5, 3.5), rng.uniform(*y_range))
        reach = np.hypot(*(np.asarray(xy) - arm.base_position[:2]))
        if arm.reach_min < reach < arm.reach_max:
            return np.r_[planar_ik(arm, xy, elbow), rng.uniform(0.0, 0.6)]


def random_path(rng, arm, elbow, strips, dt=0.05):
    """Return a stamped joint path through random poses over ``strips``, with holds."""
    poses = [random_pose(rng, arm, elbow, strip) for strip in strips]
    knots_t, knots_q = [rng.uniform(0.0, 0.5)], [poses[0]]
    for pose in poses[1:]:
        if rng.uniform() < 0.3:  # hold the last pose for a while
            knots_t.append(knots_t[-1] + rng.uniform(0.1, 0.5))
            knots_q.append(knots_q[-1])
        knots_t.append(knots_t[-1] + rng.uniform(0.3, 1.0))
        knots_q.append(pose)
    knots_q = np.array(knots_q)
    t = np.arange(knots_t[0], knots_t[-1] + 1e-9, dt)
    return t, interp_rows(t, knots_t, knots_q)


BELT = {'left': (-0.6, 0.4), 'right': (-0.4, 0.6)}
SIDE = {'left': (-2.6, -1.3), 'right': (1.3, 2.6)}


def scenario(rng, left, right, kind):
    """Return ``(t_a, q_a, t_b, q_b)`` of the arms' random paths.

    ``near``: both work at the belt all along; ``apart``: each stays on its side; ``yield``:
    a works at the belt and leaves for its side, b comes from its side to the belt.
    """
    stops = int(rng.integers(2, 5))
    strips_a = [BELT['left'] if kind != 'apart' else SIDE['left']] * stops
    strips_b = [BELT['right'] if kind != 'apart' else SIDE['right']] * stops
    if kind == 'yield':
        strips_a[-1], strips_b[0] = SIDE['left'], SIDE['right']
    t_a, q_a = random_path(rng, left, 1.0, strips_a)
    t_b, q_b = random_path(rng, right, -1.0, strips_b)
    return t_a, q_a, t_b, q_b


def brute_min(left, t_a, q_a, right, t_b, q_b, start_b=0.0, max_step=collision.MAX_TIME_STEP):
    """Return (min distance, first time) from :func:`arm_distance` at every grid time."""
    t_b = t_b + start_b
    t0, t1 = min(t_a[0], t_b[0]), max(t_a[-1], t_b[-1])
    fine = np.linspace(t0, t1, int(np.ceil((t1 - t0) / max_step)) + 1)
    times = np.unique(np.concatenate([t_a, t_b, fine]))

    dist = arm_distance(left, interp_rows(times, t_a, q_a), right, interp_rows(times, t_b, q_b))
    k = int(np.argmin(dist))
    return float(dist[k]), float(times[k])


def brute_delay(left, t_a, q_a, right, t_b, q_b, margin, max_delay, resolution=0.01,
                scan_step=0.25, max_step=collision.MAX_TIME_STEP):
    """Return :func:`smallest_safe_delay`'s search (scan, then bisection) on :func:`brute_min`."""
    if arm_distance(left, q_a[-1], right, q_b[-1]) < margin:
        return None

    def safe(k):
        return brute_min(left, t_a, q_a, right, t_b, q_b, k * resolution, max_step)[0] >= margin

    return first_safe_delay(safe, max_delay, resolution, scan_step)


def test_pair_bounds_never_exceed_the_exact_distances(arms):
    """The pair bounds never exceed the exact distances, also on a turned, tilted base.

    The exact distances of a subset are the full computation's, bit for bit.
    """
    left, right = arms
    rng = np.random.default_rng(21)
    cz, sz, cx, sx = np.cos(0.7), np.sin(0.7), np.cos(0.3), np.sin(0.3)
    base = np.array(right.base)
    base[:3, :3] = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ [[1, 0, 0], [0, cx, -sx],
                                                                       [0, sx, cx]]
    base[:3, 3] = 2.4, 0.9, 0.25
    tilted = dataclasses.replace(right, base=base)  # turned about z, tilted about x
    for other in (right, tilted):
        q_l = rng.uniform(left.lower, left.upper, (5000, 3))
        q_r = rng.uniform(other.lower, other.upper, (5000, 3))
        exact = arm_pair_distances(left, q_l, other, q_r)
        lower = collision._pair_bounds(left, q_l, other, q_r)
        assert lower.shape == (3, 3, 5000)
        assert np.all(np.moveaxis(lower, -1, 0) <= exact)
        assert np.any(exact < MARGIN)  # the random states do collide now and then
        # and the exact values computed for a subset are the full computation's, bit for bit
        i, j, n = np.nonzero(lower < 0.3)
        assert n.size > 0
        subset = collision._exact_pairs(left, q_l, other, q_r, i, j, n)
        assert np.array_equal(subset, exact[n, i, j])


@pytest.mark.parametrize('kind', ['near', 'apart'])
def test_trajectory_min_distance_is_the_full_computation(arms, kind):
    """The prefiltered trajectory minimum and its time equal the full computation's."""
    left, right = arms
    rng = np.random.default_rng(3 if kind == 'near' else 4)
    found = []
    for case in range(150 if kind == 'near' else 50):
        t_a, q_a, t_b, q_b = scenario(rng, left, right, kind)
        start_b = float(rng.choice([0.0, rng.uniform(-1.0, 3.0)]))
        max_step = float(rng.choice([collision.MAX_TIME_STEP, 0.02]))
        got = trajectory_min_distance(left, t_a, q_a, right, t_b, q_b, start_b=start_b,
                                      max_step=max_step)
        want = brute_min(left, t_a, q_a, right, t_b, q_b, start_b, max_step)
        assert got == want, (case, got, want)
        found.append(got[0])
    found = np.array(found)
    if kind == 'near':  # collisions, near misses around the margin and clear passes
        assert np.sum(found < 0.0) >= 10
        assert np.sum((found >= 0.0) & (found < 2 * MARGIN)) >= 10
        assert np.sum(found > 0.3) >= 5
    else:
        assert np.all(found > 0.5)


def test_trajectory_min_distance_returns_the_first_of_tied_minima(arms):
    """Among tied minima the first grid time is returned."""
    left, right = arms
    rng = np.random.default_rng(5)
    q_l, q_r = random_pose(rng, left, 1.0, (-0.3, 0.0)), random_pose(rng, right, -1.0, (0, 0.3))
    away_l, away_r = [-np.pi / 2, 0.5, 0.0], [np.pi / 2, -0.5, 0.0]  # home, far apart
    # Both hold their closest poses over [1, 2] s (every grid time in there ties), and again
    # over [4, 5] s.
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    q_a = np.array([away_l, q_l, q_l, away_l, q_l, q_l, away_l])
    q_b = np.array([away_r, q_r, q_r, away_r, q_r, q_r, away_r])
    d, t_min = trajectory_min_distance(left, t, q_a, right, t, q_b)
    assert (d, t_min) == brute_min(left, t, q_a, right, t, q_b)
    assert t_min == 1.0 and d == float(arm_distance(left, q_l, right, q_r))
    # Constant poses: the first grid time.
    d, t_min = trajectory_min_distance(left, [0.5, 2.0], [q_l, q_l], right, [1.0], [q_r])
    assert (d, t_min) == (float(arm_distance(left, q_l, right, q_r)), 0.5)
    # A grid of three states.
    t_a, q_a, t_b, q_b = [0.0, 0.004], np.array([away_l, q_l]), np.array([0.002]), [q_r]
    got = trajectory_min_distance(left, t_a, q_a, right, t_b, q_b)
    assert got == brute_min(left, np.array(t_a), q_a, right, t_b, np.array(q_b))
    assert got[1] == 0.004


def test_smallest_safe_delay_is_the_full_computation(arms):
    """The prefiltered smallest safe delay equals the same search on the full computation."""
    left, right = arms
    rng = np.random.default_rng(8)
    delays = []
    for case in range(40):
        kind = ('yield', 'yield', 'yield', 'near', 'apart')[case % 5]
        t_a, q_a, t_b, q_b = scenario(rng, left, right, kind)
        margin = float(rng.choice([MARGIN, rng.uniform(0.0, 0.3)]))
        max_step = 0.01
        got = smallest_safe_delay(left, t_a, q_a, right, t_b, q_b, margin, max_delay=5.0,
                                  max_step=max_step)
        want = brute_delay(left, t_a, q_a, right, t_b, q_b, margin, 5.0, max_step=max_step)
        assert got == want, (case, got, want)
        delays.append(got)
    assert sum(d == 0.0 for d in delays) >= 5
    assert sum(d is not None and d > 0.0 for d in delays) >= 5
    assert sum(d is None for d in delays) >= 1
