"""The person's scenarios: built in and from YAML, seeded, within walking and reaching speeds."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from scara_collab.core import ssm
from scara_collab.core.config import ConfigError, load_config
from scara_collab.core.scan_tracking import cell_mute_boxes, inside_boxes
from scara_collab.sim.person import body_capsules, BodyModel
from scara_collab.sim.person_scenarios import (
    BUILTIN, load_scenario, Motion, PersonPath, scenario, scenario_from_dict)

#: the built-in scenarios in which somebody comes
WALKING = tuple(n for n in BUILTIN if n != 'nobody')


@pytest.fixture(scope='module')
def cfg():
    """Return config/people.yaml."""
    return load_config('people')


def compiled(cell, cfg, name, seed=None):
    """Return the compiled path of a scenario."""
    return PersonPath(scenario(name, cell, cfg, seed), Motion.from_config(cfg))


def samples(path, step=0.02):
    """Return the times (while present) and states of a path, every ``step`` s."""
    t = np.arange(path.times[0], path.end, step)
    t = t[path.present(t)]
    return t, path.state(t)


def test_every_builtin_scenario_compiles(cell, cfg):
    """The built-in names give scenarios; none gives none; an unknown name is refused."""
    for name in WALKING:
        path = compiled(cell, cfg, name)
        assert len(path.visits) >= 1 and path.end > path.times[0]
        assert path.times[0] >= cfg['person']['earliest']  # the empty cell is taught first
    nobody = compiled(cell, cfg, 'nobody')  # the scanners and the monitor, nobody comes
    assert not nobody.visits and not nobody.present(np.arange(0.0, 100.0, 0.5)).any()
    assert scenario('none', cell, cfg) is None
    with pytest.raises(ConfigError, match='unknown person scenario'):
        scenario('dance', cell, cfg)


def test_the_random_scenario_is_reproducible_by_its_seed(cell, cfg):
    """The same seed gives the same path to the bit; another seed another path."""
    a, b = compiled(cell, cfg, 'random', 7), compiled(cell, cfg, 'random', 7)
    c = compiled(cell, cfg, 'random', 8)
    np.testing.assert_array_equal(a.times, b.times)
    np.testing.assert_array_equal(a.frames, b.frames)
    assert a.times.shape != c.times.shape or np.any(a.frames != c.frames)
    assert len(a.visits) > 10  # an hour of arrivals about a minute apart


def test_pass_by_stays_outside_every_protective_separation(cell, cfg):
    """The pass-by keeps farther from every link's reach than S_p at the arms' top speed.

    The links reach L1 + L2 plus their radius from the shoulder axis. The fastest point is the
    tool with both joints at 2 rad/s the same way, 2 * 2.5 + 2 * 1.0 = 7 m/s; it stops in
    T_s = 2 / 6 s, S_s = 7 T_s / 2 (the monitor's path-keeping stop). The person the scanner
    sees is a column of radius stance + leg + body margin; the hysteresis adds to it.
    """
    path = compiled(cell, cfg, 'pass-by')
    params = ssm.SsmParams.from_config(cfg)
    arm = cell.leader
    v = sum(arm.max_velocity[:2]) * (arm.l1 + arm.l2) - arm.max_velocity[1] * arm.l1
    assert v == pytest.approx(7.0)
    t_s = float(np.max(arm.max_velocity[:2] / arm.max_acceleration[:2]))
    s_p = float(ssm.protective_separation(params.walking_speed, v, params.reaction_time, t_s,
                                          v * t_s / 2.0, params.constant))
    body = cfg['person']['body']
    column = body['stance'] + body['leg_radius'] + cfg['monitor']['body_margin']
    needed = s_p + column + params.hysteresis
    _, states = samples(path)
    for a in cell.arms:
        reach = a.l1 + a.l2 + a.link_radius
        gap = np.linalg.norm(states[:, :2] - a.base[:2, 3], axis=1) - reach
        assert gap.min() >= needed, (a.name, gap.min(), needed)


def test_inlet_works_at_the_inlet_for_a_minute(cell, cfg):
    """The inlet scenario stands at the belt's inlet end for 60 s, leaning and reaching."""
    path = compiled(cell, cfg, 'inlet')
    t, states = samples(path, 0.05)
    at = np.abs(states[:, 0] - (cell.belt.x_start - 0.45)) < 1e-6
    assert (t[at][-1] - t[at][0]) == pytest.approx(60.0, abs=1.0)
    assert states[at, 3].max() == pytest.approx(cfg['person']['work']['lean'])
    assert states[at, 4].max() == 1.0  # reaching out
    reaching = np.diff((states[:, 4] >= 1.0).astype(int)) == 1
    assert reaching.sum() >= 15  # a reach every few seconds


def test_middle_enters_between_the_bin_and_the_pillar(cell, cfg):
    """The middle scenario reaches the belt's middle, passing no bin or pillar."""
    path = compiled(cell, cfg, 'middle')
    _, states = samples(path)
    mid = 0.5 * (cell.belt.x_start + cell.belt.x_end)
    assert np.any(np.hypot(states[:, 0] - mid, states[:, 1] + 0.9) < 1e-6)
    clear_of_obstacles(cell, cfg, states)


def clear_of_obstacles(cell, cfg, states):
    """Assert that the legs never stand on the belt or a bin, nor within a pillar."""
    body = cfg['person']['body']
    reach = body['stance'] + body['leg_radius'] + body['step_amplitude']
    boxes = cell_mute_boxes(cell, reach)
    assert not np.any(inside_boxes(states[:, :2], boxes))
    for arm in cell.arms:
        d = np.linalg.norm(states[:, :2] - arm.base[:2, 3], axis=1)
        assert d.min() > cell.config['arm']['base_radius'] + reach


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_random_visits_keep_clear_of_the_belt_bins_and_pillars(cell, cfg, seed):
    """Random paths walk around the bins and pillars and never across the belt."""
    path = compiled(cell, cfg, 'random', seed)
    _, states = samples(path, 0.05)
    clear_of_obstacles(cell, cfg, states)
    x0, x1, y0, y1 = cfg['person']['floor']
    assert np.all((states[:, 0] >= x0) & (states[:, 0] <= x1))
    assert np.all((states[:, 1] >= y0) & (states[:, 1] <= y1))


@pytest.mark.parametrize('name', WALKING)
def test_walking_and_reaching_stay_within_their_speeds(cell, cfg, name):
    """The body's centre moves at walking speed at most, the hands at reaching speed at most."""
    path = compiled(cell, cfg, name, 4)
    body = BodyModel.from_config(cfg)
    step = 0.01
    t, _ = samples(path, step)
    t = t[:20000]
    t = t[np.isin(np.round(t + step, 9), np.round(t, 9))]  # pairs within one visit
    a, b = body_capsules(body, path.state(t)), body_capsules(body, path.state(t + step))
    centre = np.linalg.norm(b.start[:, 2, :2] - a.start[:, 2, :2], axis=1) / step
    hand = np.linalg.norm(b.end[:, 5] - a.end[:, 5], axis=1) / step
    walking = max(cfg['person']['walking_speed'], cfg['person']['random']['speed'][1])
    assert walking <= 1.6  # ISO 13855's walking speed, what the monitor assumes
    assert centre.max() <= walking + 1e-6
    assert hand.max() <= cfg['person']['reach_speed'] + 1e-6


def test_a_yaml_scenario_is_read(cell, cfg, tmp_path):
    """A file of visits and waypoints: appears, walks, works, leaves."""
    f = tmp_path / 'mine.yaml'
    f.write_text('visits:\n'
                 '  - start: 3.0\n'
                 '    speed: 1.0\n'
                 '    waypoints:\n'
                 '      - [-6.0, -3.0]\n'
                 '      - {x: -1.0, y: -3.0, dwell: 5.0, face: [0.0, -3.0], work: true}\n'
                 '      - [-6.0, -3.0]\n')
    sc = scenario(str(f), cell, cfg)
    assert sc.name == 'mine' and len(sc.visits) == 1
    path = PersonPath(sc, Motion.from_config(cfg))
    assert path.times[0] == 3.0
    assert not path.present(2.9) and path.present(3.1)
    x, y = path.state(3.0 + 5.0 / 1.0 + 1.0)[:2]  # walking 5 m takes 5 s, then it works
    assert (x, y) == pytest.approx((-1.0, -3.0))
    assert path.present(path.end) and not path.present(path.end + 0.01)


@pytest.mark.parametrize('doc, message', [
    ({}, 'at least one visit'),
    ({'visits': [{'start': 2.0, 'speed': 2.5, 'waypoints': [[0, 0]]}]}, 'speed must be'),
    ({'visits': [{'start': 0.5, 'waypoints': [[0, 0]]}]}, 'start must be >= 1.0'),
    ({'visits': [{'start': 2.0, 'waypoints': [{'x': 0, 'y': 0, 'work': True, 'dwell': 1}]}]},
     'needs a face point'),
    ({'visits': [{'start': 2.0, 'waypoints': [{'x': 0, 'z': 0}]}]}, 'a waypoint is'),
    ({'visits': [{'start': 2.0, 'waypoints': [{'x': 0, 'y': 0, 'run': 1}]}]}, 'unknown'),
])
def test_bad_scenarios_are_refused_with_the_reason(doc, message):
    """A scenario that cannot be walked as asked is refused, saying why."""
    with pytest.raises(ConfigError, match=message):
        scenario_from_dict(doc, 'bad', earliest=1.0)


def test_a_missing_scenario_file_is_named(tmp_path):
    """A file that is not there is named in the error."""
    with pytest.raises(ConfigError, match='no such scenario file'):
        load_scenario(tmp_path / 'gone.yaml')


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-5.0, 5.0), y=st.floats(-5.0, 5.0), dwell=st.floats(0.0, 20.0),
       speed=st.floats(0.3, 1.6), fx=st.floats(-5.0, 5.0), fy=st.floats(-5.0, 5.0),
       work=st.booleans())
def test_a_visit_passes_every_waypoint_and_dwells_there(cell, cfg, x, y, dwell, speed, fx, fy,
                                                        work):
    """The compiled path is at each waypoint for its dwell, turned to face its point."""
    doc = {'visits': [{'start': 2.0, 'speed': speed, 'waypoints': [
        [-6.0, -6.0], {'x': x, 'y': y, 'dwell': dwell, 'face': [x + fx + 0.1, y + fy],
                       'work': work},
        [6.0, 6.0]]}]}
    path = PersonPath(scenario_from_dict(doc, 'h', 1.0), Motion.from_config(cfg))
    there = np.hypot(path.frames[:, 0] - x, path.frames[:, 1] - y) < 1e-9
    assert there.any()
    stay = path.times[there]
    assert stay[-1] - stay[0] >= dwell - 1e-9
    if dwell > 0.0:  # turned to face it while it stays
        want = math.atan2(fy, fx + 0.1)
        facing = np.cos(path.frames[there, 2] - want)
        assert facing.max() == pytest.approx(1.0, abs=1e-9)
