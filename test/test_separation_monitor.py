"""The separation monitor's decisions from scans alone: slow, stop, resume, fail closed."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from synthetic_scans import legs, pillars, scan_circles

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk
from scara_collab.core.scan_tracking import scanners_from_config
from scara_collab.core.separation_monitor import (
    MonitorSettings, nearest_person, ScaleGovernor, SeparationMonitor)
from scara_collab.core.ssm import assess_arm, Person, SsmParams

PERIOD = 1.0 / 25.0  # the scanners' period
TICK = 0.01  # the decisions' period (100 Hz)


@pytest.fixture(scope='module')
def cfg():
    """Return config/people.yaml."""
    return load_config('people')


class Cell:
    """A monitor fed exact scans of the cell's pillars and of persons given as circles."""

    def __init__(self, cell, cfg, seed=0, ghosts=0.0):
        """Teach the monitor the empty cell."""
        self.cell = cell
        self.scanners = scanners_from_config(cfg)
        self.monitor = SeparationMonitor(cell, MonitorSettings.from_config(cfg), self.scanners)
        self.rng = np.random.default_rng(seed)
        self.ghosts = ghosts
        self.static = pillars(cell)
        self.monitor.teach([[self.ranges(g, []) for _ in range(10)] for g in self.scanners])
        self.q = {a.name: np.array([0.0, 1.2 if a.name.endswith('left') else -1.2, 0.1])
                  for a in cell.arms}
        self.qd = {a.name: np.zeros(3) for a in cell.arms}
        self.time = 0.0

    def ranges(self, geometry, circles):
        """Return one scanner's noisy ranges of the pillars and ``circles`` (ghosts if asked)."""
        r = scan_circles(geometry, self.static + circles, 0.01, self.rng)
        if self.ghosts:
            ghost = self.rng.random(geometry.count) < self.ghosts
            r[ghost] = self.rng.uniform(0.5, 10.0, ghost.sum())
        return r

    def run(self, seconds, circles=lambda t: [], scans=True, on_decision=None):
        """Scan at 25 Hz and decide at 100 Hz for ``seconds``; return the decisions."""
        out = []
        for _ in range(int(round(seconds / TICK))):
            self.time = round(self.time + TICK, 9)
            if scans and abs(self.time / PERIOD - round(self.time / PERIOD)) < 1e-6:
                now = circles(self.time)
                self.monitor.observe(self.time, [self.ranges(g, now) for g in self.scanners],
                                     self.q)
            d = self.monitor.decide(self.time, {r: (self.q[r], self.qd[r]) for r in self.q})
            out.append(d)
            if on_decision:
                on_decision(d)
        return out


def scale(decisions, robot='scara_left'):
    """Return the factor of ``robot`` over the decisions."""
    return np.array([d.arm(robot).scale for d in decisions])


def test_an_untaught_monitor_stops_every_arm(cell, cfg):
    """Without the empty cell's contour nothing moves, and the decision says why."""
    monitor = SeparationMonitor(cell, MonitorSettings.from_config(cfg), scanners_from_config(cfg))
    d = monitor.decide(0.0, {a.name: (np.zeros(3), np.zeros(3)) for a in cell.arms})
    assert all(a.scale == 0.0 and a.stop for a in d.arms)
    assert 'not taught' in d.fault and d.arms[0].cause == d.fault


def test_an_empty_cell_runs_at_full_speed(cell, cfg):
    """The empty cell: no person, full speed from the first good decision on.

    The cell starts at rest, so the first look sets the factor at once; after a stop the
    factor rises only after the dwell, at the resume rate (the tests below).
    """
    sim = Cell(cell, cfg)
    s = scale(sim.run(3.0))
    first_full = np.argmax(s >= 1.0) * TICK + TICK
    assert first_full <= PERIOD + 2 * TICK  # the first scan taught, then the first decision
    assert np.all(s[int(first_full / TICK):] == 1.0)
    assert np.all(np.diff(s) >= 0.0)


def test_a_silent_scanner_stops_every_arm_within_two_periods(cell, cfg):
    """The scans stop: s = 0 with the scanner named within two scan periods; back after."""
    sim = Cell(cell, cfg)
    sim.run(2.0)
    last_scan = sim.time
    silent = sim.run(0.2, scans=False)
    zero = next(k for k, d in enumerate(silent) if all(a.scale == 0.0 for a in d.arms))
    assert (zero + 1) * TICK <= 2 * PERIOD + 1e-9
    assert all(a.stop for a in silent[zero].arms)
    assert 'scanner_a: no scan for' in silent[zero].fault
    assert sim.time - last_scan > 2 * PERIOD
    back = scale(sim.run(2.0))
    assert back[-1] == 1.0


def test_unmeasurable_ranges_stop_every_arm(cell, cfg):
    """A scan with NaN ranges (REP 117: invalid) is a protective stop, named; good scans resume."""
    sim = Cell(cell, cfg)
    sim.run(2.0)
    geometry = sim.scanners[1]
    bad = sim.ranges(geometry, [])
    bad[100:103] = np.nan
    sim.monitor.observe(sim.time, [sim.ranges(sim.scanners[0], []), bad], sim.q)
    d = sim.monitor.decide(sim.time, {r: (sim.q[r], sim.qd[r]) for r in sim.q})
    assert all(a.scale == 0.0 and a.stop for a in d.arms)
    assert d.fault == 'scanner_b: 3 rays measured nothing usable'
    assert scale(sim.run(2.0))[-1] == 1.0


def test_an_arm_without_a_finite_joint_state_stops(cell, cfg):
    """A NaN joint state stops that arm only."""
    sim = Cell(cell, cfg)
    sim.run(2.0)
    sim.q['scara_right'] = np.array([np.nan, 0.0, 0.0])
    d = sim.run(0.05)[-1]
    assert d.arm('scara_right').stop and d.arm('scara_right').scale == 0.0
    assert 'no finite joint state' in d.arm('scara_right').cause
    assert d.arm('scara_left').scale == 1.0


def test_a_person_approaching_slows_then_stops_the_arm_and_leaving_resumes_it(cell, cfg):
    """A person walks at 1.4 m/s towards the left arm, stands, walks away.

    Coming: the factor falls (never rises) and the arm stops once the person is within the
    separation at standstill; the cause names the person and the arm. Leaving: full speed
    again within 1.5 s of the separation allowing it (the dwell and the rise). The right arm,
    far away, keeps its full speed.
    """
    sim = Cell(cell, cfg)
    sim.qd['scara_left'] = np.array([1.5, -1.0, 0.0])  # planned: swinging
    sim.run(2.0)
    start = np.array([3.5, -8.0])
    stand = np.array([3.5, -3.3])
    speed = 1.4
    walk = np.linalg.norm(stand - start) / speed
    t0 = sim.time

    def where(t):
        s = t - t0
        if s < walk:
            return start + (stand - start) * s / walk
        if s < walk + 3.0:
            return stand
        return stand + (start - stand) * min(1.0, (s - walk - 3.0) / walk)

    def person(t):
        p = where(t)
        return legs(p[0], p[1], math.pi / 2)

    decisions = sim.run(2 * walk + 6.0, person)
    s = scale(decisions)
    left = [d.arm('scara_left') for d in decisions]
    coming = s[:int((walk + 3.0) / TICK)]
    assert np.all(np.diff(coming) <= 1e-12)
    assert coming[0] == 1.0 and coming[-1] == 0.0
    stopped = next(a for a in left if a.stop)
    assert 'protective stop' in stopped.cause and 'scara_left' in stopped.cause
    # resume: within 1.5 s of the first decision whose separation allows full speed
    allowed = next(k for k, a in enumerate(left) if k > len(coming) and a.required >= 1.0)
    full = next(k for k in range(allowed, len(s)) if s[k] >= 1.0)
    assert (full - allowed) * TICK <= 1.5
    assert decisions[-1].arm('scara_right').scale == 1.0  # the far arm kept working


def test_a_person_appearing_inside_the_separation_stops_the_arm_at_the_first_scan(cell, cfg):
    """Out of sight (behind an occlusion), then seen within S_p at standstill of a moving arm.

    The first decision on the scan that shows them is a protective stop, the factor 0 at once
    (no fall at the braking rate: a required 0 is a stop); the arm far away runs on.
    """
    sim = Cell(cell, cfg)
    sim.qd['scara_left'] = np.array([1.5, -1.0, 0.0])
    sim.run(2.0)
    inside = legs(2.7, -2.9)  # 0.8 m from the left arm's link 1: S_p at standstill is 1.38 m
    decisions = sim.run(0.2, lambda t: inside)
    first = next(k for k, d in enumerate(decisions) if d.persons)
    seen = decisions[first].arm('scara_left')
    assert seen.stop and seen.scale == 0.0 and 'at standstill: protective stop' in seen.cause
    assert (first + 1) * TICK <= PERIOD + 1e-9  # within the scan period it came in
    assert decisions[-1].arm('scara_right').scale == 1.0


def test_a_person_standing_inside_holds_the_arm_until_they_leave(cell, cfg):
    """Standing within S_p at standstill for 5 s: no resume; gone, full speed within 1.5 s."""
    sim = Cell(cell, cfg)
    sim.qd['scara_left'] = np.array([1.5, -1.0, 0.0])
    sim.run(2.0)
    inside = legs(2.7, -2.9)
    standing = sim.run(5.0, lambda t: inside)
    k = next(k for k, d in enumerate(standing) if d.persons)
    assert all(d.arm('scara_left').scale == 0.0 and d.arm('scara_left').stop
               for d in standing[k:])
    away = scale(sim.run(3.0))
    full = next(k for k, v in enumerate(away) if v >= 1.0)
    assert full * TICK <= 1.5 + PERIOD + cfg['monitor']['track_hold']


def test_the_monitor_reads_scans_not_where_the_person_is(cell, cfg):
    """Two persons are found where the scans put them: tracked columns, not true bodies."""
    sim = Cell(cell, cfg)
    sim.run(1.0, lambda t: legs(-2.0, -5.0) + legs(6.0, 5.0))
    persons = sim.monitor.persons(sim.time)
    assert len(persons) == 2
    found = sorted(tuple(np.round(p.position, 1)) for p in persons)
    assert found[0] == pytest.approx((-2.0, -5.0), abs=0.15)
    assert found[1] == pytest.approx((6.0, 5.0), abs=0.15)


def test_the_nearest_person_is_the_one_with_the_smallest_separation(cell, cfg):
    """Of several columns, the one nearest to the arm's capsules, as ``assess_arm`` measures S."""
    arm = cell.leader
    q = np.array([0.3, 1.0, 0.1])
    params = SsmParams.from_config(cfg)
    rng = np.random.default_rng(1)
    assert nearest_person(arm, q, ()) is None
    for _ in range(20):
        persons = tuple(Person(rng.uniform(-4.0, 6.0, 2), np.zeros(2), rng.uniform(0.1, 0.5),
                               2.0, k) for k in range(3))
        near = nearest_person(arm, q, persons)
        seps = [assess_arm(arm, q, np.zeros(3), [p], params).separation for p in persons]
        assert near.id == int(np.argmin(seps))


def test_ghost_points_do_not_slow_the_arms(cell, cfg):
    """Spurious single returns (about one a scan) never change the factor of an empty cell."""
    sim = Cell(cell, cfg, seed=3, ghosts=0.001)
    s = scale(sim.run(6.0))
    assert np.all(s[int(1.3 / TICK):] == 1.0)


def test_a_held_item_at_the_quill_is_muted(cell, cfg):
    """An item under the left quill, in the scan plane off the belt, is the arm, not a person."""
    sim = Cell(cell, cfg)
    sim.q['scara_left'] = np.array([-0.4, 1.0, 0.5])
    tool = fk(cell.leader, sim.q['scara_left'])[:2]
    assert abs(tool[1]) > 1.0  # off the belt
    s = scale(sim.run(3.0, lambda t: [(tool[0], tool[1], 0.07)]))
    assert s[-1] == 1.0 and not sim.monitor.tracker.tracks


def test_governor_falls_at_the_braking_rate_and_rises_after_the_dwell():
    """Falling: at most the braking rate; rising: after the dwell, at the resume rate."""
    gov = ScaleGovernor(dwell=0.2, resume_rate=1.0)
    gov.scale = 1.0
    gov.update(0.0, 1.0, 1.0, 3.0)
    assert gov.update(0.1, 0.2, 0.2, 3.0) == pytest.approx(0.7)  # 3 /s for 0.1 s
    assert gov.update(0.2, 0.2, 0.2, 3.0) == pytest.approx(0.4)
    assert gov.update(0.3, 0.2, 0.2, 3.0) == pytest.approx(0.2)  # not below what is allowed
    assert gov.update(0.4, 0.0, 0.0, 3.0) == 0.0  # a stop is immediate
    assert gov.update(0.5, 1.0, 1.0, 3.0) == 0.0  # the dwell starts
    assert gov.update(0.65, 1.0, 1.0, 3.0) == 0.0
    assert gov.update(0.8, 1.0, 1.0, 3.0) == pytest.approx(0.1)  # 0.1 s past the dwell
    assert gov.update(2.0, 1.0, 1.0, 3.0) == 1.0


@settings(max_examples=50, deadline=None)
@given(level=st.floats(0.2, 0.8), wobble=st.floats(0.0, 0.02), seed=st.integers(0, 99))
def test_governor_does_not_chatter(level, wobble, seed):
    """A separation wobbling around one level moves the factor one way, not back and forth."""
    rng = np.random.default_rng(seed)
    gov = ScaleGovernor(dwell=0.2, resume_rate=1.0)
    out = []
    for k in range(300):
        required = level + rng.uniform(-wobble, wobble)
        relaxed = required - 0.05  # the hysteresis: 0.1 m is worth about this much
        out.append(gov.update(k * TICK, required, relaxed, 3.0))
    turns = np.count_nonzero(np.diff(np.sign(np.diff(out))[np.diff(out) != 0]))
    assert turns <= 2


def test_an_arm_is_weighed_at_its_planned_and_its_measured_speed_the_lower_factor_taken(cell,
                                                                                        cfg):
    """The speed towards a person is directed: neither velocity bounds the other.

    A person stands near the left arm. Swinging one way the arm is allowed less than the other
    way; planned one way and measured the other (a reversal after a hold), it is allowed the
    lower of the two, and a velocity of one of them alone is weighed as before.
    """
    sim = Cell(cell, cfg)
    sim.run(2.0)
    sim.run(0.5, lambda t: legs(3.5, -4.0))
    robot, q = 'scara_left', sim.q['scara_left']
    swing = np.array([1.5, -1.0, 0.0])

    def required(*velocities):
        d = sim.monitor.decide(sim.time, {robot: (q, *velocities)})
        return d.arm(robot).required

    one, other = required(swing), required(-swing)
    assert one != other and min(one, other) < 1.0
    assert required(swing, -swing) == required(-swing, swing) == min(one, other)
    assert required(swing, np.zeros(3)) == one  # measured at rest: the planned one counts
    assert required(np.zeros(3), swing) == one  # nothing planned, still moving: the measured
