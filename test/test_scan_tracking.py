"""From scans to tracked persons: contour, foreground, muting, clusters, tracks (no ROS)."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from numpy.testing import assert_allclose
from synthetic_scans import legs, scan_circles

from scara_collab.core import scan_tracking as st_
from scara_collab.core.config import load_config

GEOMETRY = st_.ScanGeometry('scanner_a', -6.0, -7.0, math.pi / 4, -3 * math.pi / 4,
                            1.5 * math.pi / 540, 541, 0.05, 20.0, 0.3)


def test_scanners_from_the_config_cover_their_field_of_view():
    """Both scanners: 541 rays across 270 deg centred on the yaw, at the scan height."""
    a, b = st_.scanners_from_config(load_config('people'))
    assert (a.name, b.name) == ('scanner_a', 'scanner_b')
    assert a.count == 541 and a.height == 0.3
    assert_allclose(a.directions[0], [0.0, -1.0], atol=1e-9)  # 45 deg - 135 deg
    assert_allclose(a.directions[-1], [-1.0, 0.0], atol=1e-9)  # 45 deg + 135 deg


def test_points_are_where_the_rays_end():
    """A ray's point is the scanner's position plus the range along the ray."""
    ranges = scan_circles(GEOMETRY, [(0.0, 0.0, 0.5)])
    pts = GEOMETRY.points(ranges, np.isfinite(ranges))
    dist = np.linalg.norm(pts - [0.0, 0.0], axis=1)
    assert len(pts) > 3
    assert_allclose(dist, 0.5, atol=1e-9)  # on the circle


def test_the_contour_removes_the_static_cell():
    """Taught from noisy scans of the empty cell, no later scan of it has a foreground ray."""
    rng = np.random.default_rng(1)
    pillars = [(2.0, -2.0, 0.12), (2.0, 2.0, 0.12)]
    contour = st_.teach_contour([scan_circles(GEOMETRY, pillars, 0.01, rng) for _ in range(10)],
                                GEOMETRY.range_max)
    assert np.isfinite(contour).sum() > 0 and np.isinf(contour).sum() > 400
    for _ in range(50):
        ranges = scan_circles(GEOMETRY, pillars, 0.01, rng)
        assert not st_.foreground(ranges, contour, 0.1, GEOMETRY.range_max).any()
    ranges = scan_circles(GEOMETRY, pillars + legs(0.0, -4.0), 0.01, rng)
    fg = st_.foreground(ranges, contour, 0.1, GEOMETRY.range_max)
    assert fg.sum() >= 2
    pts = GEOMETRY.points(ranges, fg)
    assert np.all(np.linalg.norm(pts - [0.0, -4.0], axis=1) < 0.2)


def test_range_faults_count_what_cannot_be_measured():
    """NaN, -inf and ranges below range_min are faults; +inf (no return) is not (REP 117)."""
    ranges = np.full(GEOMETRY.count, np.inf)
    assert st_.range_faults(ranges, GEOMETRY) == 0
    ranges[[3, 7, 9]] = [np.nan, -np.inf, 0.01]
    assert st_.range_faults(ranges, GEOMETRY) == 3
    assert st_.range_faults(ranges[:10], GEOMETRY) == GEOMETRY.count


def test_the_belt_bins_and_quills_are_muted(cell):
    """Points on the belt or a bin, or at a quill, are muted; a point on the floor is not."""
    boxes = st_.cell_mute_boxes(cell, 0.05)
    assert len(boxes) == 1 + len(cell.bins)
    pts = np.array([[2.0, 0.0], [0.6, -2.1], [-0.6, 0.0], [2.0, -1.0]])
    assert list(st_.inside_boxes(pts, boxes)) == [True, True, False, False]
    near = st_.near_points(pts, np.array([[2.0, -1.1]]), 0.15)
    assert list(near) == [False, False, False, True]


@settings(max_examples=50, deadline=None)
@given(n=st.integers(1, 6), gap=st.floats(0.6, 3.0), seed=st.integers(0, 1000))
def test_clusters_are_the_connected_groups(n, gap, seed):
    """Blobs farther apart than the gap are separate clusters; each blob is one."""
    rng = np.random.default_rng(seed)
    centres = np.arange(n)[:, None] * np.array([gap + 0.5 + 0.4, 0.0])
    pts = np.concatenate([c + rng.uniform(-0.2, 0.2, (5, 2)) for c in centres])
    found = st_.clusters(rng.permutation(pts), 0.5)
    assert len(found) == n
    assert sorted(c.count for c in found) == [5] * n
    assert_allclose(sorted(c.centre[0] for c in found), centres[:, 0], atol=0.2)


WINDOW = 0.5  # s, the velocity window of config/people.yaml


def track_walk(speed, heading, ghosts=0.0, seconds=2.0, seed=0, start=(-2.0, -5.0)):
    """Scan a person walking from ``start`` at 25 Hz; return the tracker and the true path.

    The legs swing fore and aft as the simulated person's do (0.2 m, 0.7 m steps).
    """
    rng = np.random.default_rng(seed)
    tracker = st_.Tracker(0.5, 1.0, WINDOW, 2)
    v = speed * np.array([math.cos(heading), math.sin(heading)])
    truth = []
    for k in range(int(seconds * 25)):
        t = k / 25.0
        x, y = np.array(start) + v * t
        phase = math.pi * speed * t / 0.7
        stride = 0.2 * math.sin(phase) * np.array([math.cos(heading), math.sin(heading)])
        (lx, ly, r), (rx, ry, _) = legs(x, y, heading)
        circles = [(lx + stride[0], ly + stride[1], r), (rx - stride[0], ry - stride[1], r)]
        ranges = scan_circles(GEOMETRY, circles, 0.01, rng)
        if ghosts:
            k_ghost = rng.random(GEOMETRY.count) < ghosts
            ranges[k_ghost] = rng.uniform(1.0, 15.0, k_ghost.sum())
        pts = GEOMETRY.points(ranges, np.isfinite(ranges))
        tracker.update(t, st_.clusters(pts, 0.5))
        truth.append((x, y))
    return tracker, np.array(truth), v


def test_a_walking_persons_speed_is_estimated():
    """A person walking at 0.8 to 1.6 m/s is tracked, its velocity within 0.25 m/s mostly.

    One track in any direction, near the true position; the velocity within 0.25 m/s in 9
    cases of 10 and 0.5 m/s in all (the swinging legs move the centre seen).
    """
    errors = []
    for speed in (0.8, 1.2, 1.6):
        for heading in np.linspace(-3.0, 3.0, 7):
            tracker, truth, v = track_walk(speed, heading)
            assert len(tracker.tracks) == 1
            track = tracker.tracks[0]
            assert np.linalg.norm(track.position - truth[-1]) < 0.15
            errors.append(np.linalg.norm(track.velocity(WINDOW) - v))
    assert np.quantile(errors, 0.9) < 0.25 and max(errors) < 0.5


def test_single_ghost_points_are_ignored():
    """Spurious single returns (1 in 200 rays) make no track; the person is still tracked."""
    tracker, truth, v = track_walk(1.2, 0.5, ghosts=0.005, seed=4)
    assert len(tracker.tracks) == 1
    assert np.linalg.norm(tracker.tracks[0].position - truth[-1]) < 0.15
    empty = st_.Tracker(0.5, 1.0, WINDOW, 2)
    rng = np.random.default_rng(5)
    last = np.full(2, 100.0)
    for k in range(100):  # one ghost a scan, never in the same place twice running
        ghost = rng.uniform(-5.0, 5.0, 2)
        while np.linalg.norm(ghost - last) < 1.0:
            ghost = rng.uniform(-5.0, 5.0, 2)
        last = ghost
        empty.update(k / 25.0, st_.clusters(ghost[None], 0.5))
        assert not empty.tracks


def test_a_sparse_person_seen_twice_counts():
    """A one-return cluster becomes a person when it is seen again where it was."""
    tracker = st_.Tracker(0.5, 1.0, WINDOW, 2)
    one = [st_.Cluster(np.array([1.0, 1.0]), 0.0, 1)]
    assert tracker.update(0.0, one) == []
    assert len(tracker.update(0.04, one)) == 1


def test_a_person_not_seen_is_held_then_dropped():
    """A track is kept for ``hold`` seconds after it was last seen, then dropped."""
    tracker = st_.Tracker(0.5, 1.0, 0.3, 2)
    tracker.update(0.0, [st_.Cluster(np.array([1.0, 1.0]), 0.1, 4)])
    assert len(tracker.update(0.96, [])) == 1
    assert tracker.update(1.04, []) == []


def test_velocity_needs_half_a_window_of_history():
    """With too little history the velocity is unknown (zeros): the walking speed is assumed."""
    track = st_.Track(1, np.zeros(2), 0.1, 0.04, [0.0, 0.04], [np.zeros(2), np.ones(2)])
    assert_allclose(track.velocity(0.3), 0.0)
