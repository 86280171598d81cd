"""The simulated safety laser scanner: ranges against the geometry, the contour, its cost."""
import math
import time

import numpy as np
from numpy.testing import assert_allclose
import pytest
from synthetic_scans import legs, pillars, scan_circles

from scara_collab.core.config import load_config
from scara_collab.core.scan_tracking import foreground, scanners_from_config, teach_contour
from scara_collab.core.separation_monitor import MonitorSettings, SeparationMonitor
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.person import arm_distance, arm_link_names, BodyModel, PersonSim
from scara_collab.sim.person_scenarios import Motion, PersonPath, scenario, scenario_from_dict
from scara_collab.sim.scanner import rays_towards, SafetyScanner


@pytest.fixture(scope='module')
def cfg():
    """Return config/people.yaml."""
    return load_config('people')


@pytest.fixture(scope='module')
def sim():
    """Return a cell simulator (one per module)."""
    with CellSim() as s:
        yield s


def exact(sim, cfg):
    """Return a noiseless scanner of the config's geometry in the simulator's world."""
    return SafetyScanner(sim.client, scanners_from_config(cfg), cfg['scanner']['rate'])


def person_at(sim, cfg, x, y, face):
    """Return a person standing still at (x, y) from 2 s on (not working), posed at 3 s."""
    doc = {'visits': [{'start': 2.0, 'waypoints': [
        {'x': x, 'y': y, 'dwell': 100.0, 'face': list(face)}]}]}
    path = PersonPath(scenario_from_dict(doc, 'stand', 1.0), Motion.from_config(cfg))
    person = PersonSim(sim.client, BodyModel.from_config(cfg), path, 0,
                       arm_link_names(sim.client, 0, sim.cell.arms))
    person.update(3.0)
    return person


def test_the_empty_cell_shows_the_pillars(sim, cfg):
    """Without a person the scan meets only the pillars, where their cylinders are."""
    scanner = exact(sim, cfg)
    for geometry, ranges in zip(scanner.scanners, scanner.scan()):
        expected = scan_circles(geometry, pillars(sim.cell))
        assert np.isfinite(ranges).sum() == np.isfinite(expected).sum() > 0
        assert_allclose(ranges[np.isfinite(ranges)], expected[np.isfinite(expected)],
                        atol=0.01)  # grazing rays: PyBullet's cylinders within mm


def test_a_person_gives_the_ranges_of_its_legs(sim, cfg):
    """A person standing at a known place: the rays end on its leg capsules' circles."""
    scanner = exact(sim, cfg)
    body = BodyModel.from_config(cfg)
    person = person_at(sim, cfg, -1.0, -4.0, (0.0, -4.0))  # facing +x: legs at y -4 -+ 0.1
    try:
        circles = pillars(sim.cell) + legs(-1.0, -4.0, 0.0, body.stance, body.leg_radius)
        for geometry, ranges in zip(scanner.scanners, scanner.scan()):
            expected = scan_circles(geometry, circles)
            assert np.array_equal(np.isfinite(ranges), np.isfinite(expected))
            assert_allclose(ranges[np.isfinite(ranges)], expected[np.isfinite(expected)],
                            atol=0.01)  # grazing rays: PyBullet's cylinders within mm
            on_legs = scan_circles(geometry, circles[2:])
            assert np.isfinite(on_legs).sum() >= 2  # each scanner sees the person
    finally:
        person.close()


def test_the_taught_contour_removes_the_static_cell(sim, cfg):
    """Taught from noisy scans of the empty cell: no foreground later, except the person."""
    scanner = SafetyScanner.from_config(sim.client, cfg)
    taught = [scanner.scan() for _ in range(cfg['monitor']['teach_scans'])]
    contours = [teach_contour([t[i] for t in taught], g.range_max)
                for i, g in enumerate(scanner.scanners)]
    threshold = cfg['monitor']['foreground']
    for _ in range(100):
        for g, c, r in zip(scanner.scanners, contours, scanner.scan()):
            assert not foreground(r, c, threshold, g.range_max).any()
    person = person_at(sim, cfg, 5.0, 4.0, (5.0, 0.0))
    try:
        for g, c, r in zip(scanner.scanners, contours, scanner.scan()):
            pts = g.points(r, foreground(r, c, threshold, g.range_max))
            assert len(pts) >= 2
            assert np.all(np.linalg.norm(pts - [5.0, 4.0], axis=1) < 0.2)
    finally:
        person.close()


def test_noise_and_ghosts_are_seeded(sim, cfg):
    """The same seed gives the same noisy scans; ghosts are short returns now and then."""
    geometry = scanners_from_config(cfg)
    a = SafetyScanner(sim.client, geometry, 25.0, 0.01, seed=9, ghost_probability=0.01)
    b = SafetyScanner(sim.client, geometry, 25.0, 0.01, seed=9, ghost_probability=0.01)
    clean = exact(sim, cfg).scan()
    for _ in range(5):
        for ra, rb, rc, g in zip(a.scan(), b.scan(), clean, geometry):
            np.testing.assert_array_equal(ra, rb)
            ghosts = np.isfinite(ra) & ~np.isfinite(rc)
            assert np.all(ra[np.isfinite(ra)] >= g.range_min)
            assert ghosts.sum() <= 0.05 * g.count
    noisy, true = np.concatenate(a.scan()), np.concatenate(clean)
    both = np.isfinite(noisy) & np.isfinite(true)
    assert np.std(noisy[both] - true[both]) < 0.05


def _crossing(g, box):
    """Return which rays of ``g`` cross ``box`` (xmin, ymin, xmax, ymax) within range: exact."""
    enter, leave = np.zeros(g.count), np.full(g.count, g.range_max)
    for axis in (0, 1):
        d = g.directions[:, axis]
        lo, hi = box[axis] - g.origin[axis], box[axis + 2] - g.origin[axis]
        with np.errstate(divide='ignore', invalid='ignore'):
            near, far = lo / d, hi / d
        inside = lo <= 0.0 <= hi
        first = np.where(d != 0.0, np.minimum(near, far), -np.inf if inside else np.inf)
        last = np.where(d != 0.0, np.maximum(near, far), np.inf if inside else -np.inf)
        enter, leave = np.maximum(enter, first), np.minimum(leave, last)
    return enter <= leave


def test_the_rays_towards_a_box_are_every_ray_that_crosses_it_and_two_more(cfg):
    """The culling's rays (by the box's bearings) hold every ray that crosses it (slab test).

    Random boxes around each scanner, near and far, thin and wide, on every side (across the
    bearing of its first ray too): no crossing ray is left out, at most one more on each side.
    """
    rng = np.random.default_rng(11)
    for g in scanners_from_config(cfg):
        for _ in range(3000):
            centre = g.origin + rng.uniform(-8.0, 8.0, 2)
            half = rng.uniform(0.005, 1.0, 2)
            box = np.concatenate([centre - half, centre + half])
            if np.hypot(*np.max(np.abs(np.reshape(box, (2, 2)) - g.origin), axis=0)) > g.range_max:
                continue  # beyond the rays' length: the bearings do not look at it
            mask, exact = rays_towards(g, box[None]), _crossing(g, box)
            assert not np.any(exact & ~mask), box
            if not exact.all():
                assert mask.sum() <= exact.sum() + 2, box


def test_culling_casts_fewer_rays_and_changes_no_range(cfg):
    """Casting only the rays something crossed gives every scan of casting them all, bitwise.

    The arms jump between random poses at every scan (the quills through their whole stroke),
    items come and go on the belt, a person walks to the inlet and leans over the belt; two
    scanners in one world, one culling, one casting every ray, with the same noise.
    """
    rng = np.random.default_rng(5)
    geometry = scanners_from_config(cfg)
    with CellSim() as sim:
        culled = SafetyScanner(sim.client, geometry, 25.0, 0.01, seed=3, ghost_probability=0.01)
        every = SafetyScanner(sim.client, geometry, 25.0, 0.01, seed=3, ghost_probability=0.01,
                              cull=False)
        path = PersonPath(scenario('inlet', sim.cell, cfg, 1), Motion.from_config(cfg))
        person = PersonSim(sim.client, BodyModel.from_config(cfg), path, sim.body,
                           arm_link_names(sim.client, sim.body, sim.cell.arms))
        cast = full = 0
        try:
            t0 = path.visits[0][0]  # as the person appears
            for k in range(400):
                t = t0 + k * 0.04
                if k % 3 == 0:
                    for a in sim.cell.arms:
                        sim.reset_arm(a.name, rng.uniform(a.lower, a.upper))
                sim.step(int(round(0.04 / sim.dt)))
                person.update(t)
                for a, b in zip(culled.scan(), every.scan()):
                    np.testing.assert_array_equal(a, b)
                cast += culled.cast
                full += every.cast
        finally:
            person.close()
    print(f'culled: {cast / 400:.0f} rays cast per scan of {full / 400:.0f}')
    assert cast < 0.5 * full


def test_culling_sees_a_body_that_goes_and_one_that_takes_its_id(sim, cfg):
    """A body removed is cast through again; a new one that takes its id is seen where it is."""
    geometry = scanners_from_config(cfg)
    culled = SafetyScanner(sim.client, geometry, 25.0)
    every = SafetyScanner(sim.client, geometry, 25.0, cull=False)
    pb = sim.client
    column = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=0.2, height=1.0)

    def same():
        for a, b in zip(culled.scan(), every.scan()):
            np.testing.assert_array_equal(a, b)

    same()
    first = pb.createMultiBody(0.0, column, -1, [-3.0, -5.0, 0.5])
    same()
    pb.removeBody(first)
    same()
    second = pb.createMultiBody(0.0, column, -1, [5.0, 5.0, 0.5])
    try:
        assert second == first  # PyBullet gives the id again
        same()
        assert culled.cast > 0
    finally:
        pb.removeBody(second)
    same()


def test_a_scan_is_cheap(sim, cfg):
    """CPU per scan (both scanners) and per sim second at 25 Hz, reported; a loose bound.

    Every ray cast (the cost of a scan when everything at the scan plane moves), and culled in
    the still cell (a look at every link's box, no ray).
    """
    sc = cfg['scanner']
    for cull in (False, True):
        scanner = SafetyScanner(sim.client, scanners_from_config(cfg), sc['rate'], sc['noise'],
                                cull=cull)
        for _ in range(10):
            scanner.scan()
        best = math.inf
        for _ in range(5):
            t0 = time.process_time()
            for _ in range(50):
                scanner.scan()
            best = min(best, (time.process_time() - t0) / 50)
        rays = sum(g.count for g in scanner.scanners)
        assert scanner.cast == (0 if cull else rays)  # the still cell: nothing to cast again
        print(f'scan of {rays} rays, {"culled" if cull else "every ray cast"}: '
              f'{best * 1e3:.2f} ms CPU; at {sc["rate"]:.0f} Hz '
              f'{best * sc["rate"] * 1e3:.1f} ms per sim second')
        assert best < 5e-3


def test_a_person_passing_by_costs_nothing(sim, cfg):
    """The pass-by, scanned and monitored: both arms keep full speed at their top speeds.

    The arms hold their home poses while their planned joint speeds are at the limits (the
    fastest an arm could be moving when the person passes): the monitor never slows them.
    """
    scanner = SafetyScanner.from_config(sim.client, cfg)
    monitor = SeparationMonitor(sim.cell, MonitorSettings.from_config(cfg), scanner.scanners)
    monitor.teach([np.array(k) for k in zip(*[scanner.scan() for _ in range(10)])])
    path = PersonPath(scenario('pass-by', sim.cell, cfg), Motion.from_config(cfg))
    person = PersonSim(sim.client, BodyModel.from_config(cfg), path, 0,
                       arm_link_names(sim.client, 0, sim.cell.arms))
    q = {a.name: sim.arm_state(a.name)[0] for a in sim.cell.arms}
    planned = {a.name: (q[a.name], a.max_velocity * np.array([1.0, 1.0, 1.0]))
               for a in sim.cell.arms}
    seen = 0
    try:
        t = 0.0
        while t < path.end + 0.5:
            t = round(t + scanner.period, 9)
            person.update(t)
            monitor.observe(t, scanner.scan(), q)
            d = monitor.decide(t, planned)
            seen = max(seen, len(d.persons))
            if t > 1.5:  # past the factor's first rise
                assert all(a.scale == 1.0 for a in d.arms), d
    finally:
        person.close()
    assert seen == 1  # it was seen


def test_the_monitor_sees_a_person_at_the_belt_and_c_covers_its_reach(sim, cfg):
    """The middle scenario, scanned and monitored, the arms at home at their top speeds.

    Whatever the person does, its true body is never nearer an arm than the column the
    monitor sees, less C (what the scan cannot see, C covers); while it works at the belt the
    left arm, whose links it could reach, is stopped.
    """
    scanner = SafetyScanner.from_config(sim.client, cfg)
    monitor = SeparationMonitor(sim.cell, MonitorSettings.from_config(cfg), scanner.scanners)
    monitor.teach([np.array(k) for k in zip(*[scanner.scan() for _ in range(10)])])
    path = PersonPath(scenario('middle', sim.cell, cfg), Motion.from_config(cfg))
    person = PersonSim(sim.client, BodyModel.from_config(cfg), path, 0,
                       arm_link_names(sim.client, 0, sim.cell.arms))
    q = {a.name: sim.arm_state(a.name)[0] for a in sim.cell.arms}
    planned = {a.name: (q[a.name], a.max_velocity.copy()) for a in sim.cell.arms}
    c = monitor.settings.ssm.intrusion
    working = stopped = 0
    try:
        t = 0.0
        while t < path.end + 0.5:
            t = round(t + scanner.period, 9)
            person.update(t)
            monitor.observe(t, scanner.scan(), q)
            d = monitor.decide(t, planned)
            caps = person.capsules()
            if caps is None or not d.persons:
                continue
            for a in sim.cell.arms:
                truth = arm_distance(caps, a, q[a.name])
                assert truth >= d.arm(a.name).separation - c - 0.05
            if path.state(t)[4] > 0.5:  # reaching over the belt
                working += 1
                stopped += d.arm('scara_left').stop
    finally:
        person.close()
    assert working > 0 and stopped == working
