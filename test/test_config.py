"""Configuration: SPEC defaults load, bad values are refused with clear errors."""
import copy
from pathlib import Path

import pytest
import yaml

from scara_collab.core.config import ConfigError, load_all, load_config, validate
from scara_collab.core.model import load_cell, parse_urdf
from scara_collab.core.paths import config_dir


def test_all_files_load_with_spec_defaults():
    """Every configuration file loads, with the SPEC's defaults."""
    cfg = load_all()
    cell, sim, ctl = cfg['cell'], cfg['simulation'], cfg['controllers']
    assert cell['joints']['revolute_velocity'] == 2.0
    assert cell['collision']['safety_margin'] == 0.10
    assert cell['belt']['speed'] == 0.2
    assert [cell['profiles'][p]['link_thickness'] for p in ('slim', 'default', 'heavy')] == [
        0.05, 0.10, 0.15]
    assert sim['physics_rate'] == 1000.0 and sim['solver_iterations'] == 50
    assert sim['gravity'] == [0.0, 0.0, -9.81]
    assert sim['servo_rate'] == 250.0 and sim['item_rate'] == 100.0
    assert sim['state_rate'] == 100.0  # SPEC: /joint_states at 100 Hz sim time
    assert sim['feed_interval'] == 1.8 and sim['feed_pattern'] == 'random'
    assert sim['lateral_jitter'] == 0.3 and sim['grasp_tolerance'] == 0.06
    assert ctl['trajectory']['sample_period'] == 0.01  # planned points at 100 Hz
    assert ctl['pid']['planar'] == {'kp': 15.0, 'ki': 0.5, 'kd': 2.0}
    assert ctl['pid']['quill'] == {'kp': 10.0, 'ki': 0.1, 'kd': 1.0}


def _cell():
    return copy.deepcopy(load_config('cell'))


@pytest.mark.parametrize('mutate, message', [
    (lambda c: c['arm'].pop('link_1_length'), "missing required key 'arm.link_1_length'"),
    (lambda c: c['arm'].update(link_1_length=-1.0), 'arm.link_1_length must be a number > 0'),
    (lambda c: c['arm'].update(link_2_length='long'), 'arm.link_2_length must be a number > 0'),
    (lambda c: c['arm'].update(profile='chunky'), "arm.profile 'chunky' is not one of"),
    (lambda c: c['joints'].update(revolute_limit=4.0), 'joints.revolute_limit must be <= pi'),
    (lambda c: c['reach'].update(max_radius=3.0), 'reach must satisfy'),
    (lambda c: c['robots'].update(names=['a']), 'robots.names must name exactly two'),
    (lambda c: c['robots']['scara_left'].update(base_xyz=[1, 2]), 'base_xyz must be a list of 3'),
    (lambda c: c['belt'].update(x_end=-5.0), 'belt.x_end must be greater'),
    (lambda c: c['profiles']['slim'].update(link_thickness=0), 'profiles.slim.link_thickness'),
    (lambda c: c['arm'].update(link_density=float('nan')), 'arm.link_density must be'),
])
def test_invalid_cell_values_are_refused_with_the_key(mutate, message):
    """Each invalid cell value is refused with an error naming its key."""
    cfg = _cell()
    mutate(cfg)
    with pytest.raises(ConfigError, match=message.replace('(', r'\(')):
        validate('cell', cfg)


def test_other_files_are_validated():
    """Invalid simulation, controllers and automation values are refused."""
    sim = copy.deepcopy(load_config('simulation'))
    sim['physics_rate'] = 5.0
    with pytest.raises(ConfigError, match='physics_rate must be in'):
        validate('simulation', sim)
    for key, value, message in (('feed_pattern', 'zigzag', "feed_pattern must be 'random'"),
                                ('feed_interval', -1.0, 'feed_interval must be a number >= 0'),
                                ('servo_rate', 0.0, 'servo_rate must be a number > 0')):
        sim = copy.deepcopy(load_config('simulation'))
        sim[key] = value
        with pytest.raises(ConfigError, match=message):
            validate('simulation', sim)
    sim = copy.deepcopy(load_config('simulation'))
    sim['feed_interval'] = 0.0  # no automatic feed
    validate('simulation', sim)
    ctl = copy.deepcopy(load_config('controllers'))
    ctl['control_mode'] = 'bang_bang'
    with pytest.raises(ConfigError, match="control_mode must be 'pid' or 'computed_torque'"):
        validate('controllers', ctl)
    auto = copy.deepcopy(load_config('automation'))
    auto['mode'] = 'solo'
    with pytest.raises(ConfigError, match='mode must be'):
        validate('automation', auto)


def test_people_file_holds_the_spec_defaults():
    """people.yaml: scan plane 0.3 m, 25 Hz, v_h 1.6 m/s (2.0 reaching), Z_d 0.1 m."""
    cfg = load_config('people')
    assert cfg['person']['scenario'] == 'none'
    assert cfg['scanner']['height'] == 0.3 and cfg['scanner']['rate'] == 25.0
    assert cfg['monitor']['walking_speed'] == 1.6 and cfg['monitor']['reach_speed'] == 2.0
    assert cfg['monitor']['sensor_tolerance'] == 0.1


@pytest.mark.parametrize('mutate, message', [
    (lambda c: c['scanner'].update(height=1.5), 'scanner.height must be <= 1.0 m'),
    (lambda c: c['scanner']['scanner_b'].update(pose=[1.0, 2.0]), 'scanner.scanner_b.pose'),
    (lambda c: c['person'].update(walking_speed=1.8), 'must not exceed monitor.walking_speed'),
    (lambda c: c['person']['random'].update(dwell=[5.0, 1.0]), 'person.random.dwell'),
    (lambda c: c['monitor'].update(stale_after=0.0), 'monitor.stale_after must be a number > 0'),
    (lambda c: c['scanner'].update(range_min=30.0), 'range_min must be less than'),
])
def test_invalid_people_values_are_refused_with_the_key(mutate, message):
    """Each invalid people value is refused with an error naming its key."""
    cfg = copy.deepcopy(load_config('people'))
    mutate(cfg)
    with pytest.raises(ConfigError, match=message):
        validate('people', cfg)


def test_unreadable_files_say_what_is_wrong(tmp_path):
    """Missing, malformed, flat and unknown configuration files each say what is wrong."""
    with pytest.raises(ConfigError, match='no such configuration file'):
        load_config('cell', tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('just: [a, list\n')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_config('cell', bad)
    flat = tmp_path / 'flat.yaml'
    flat.write_text('speed: 1\n')
    with pytest.raises(ConfigError, match='ros__parameters'):
        load_config('cell', flat)
    with pytest.raises(ConfigError, match='unknown configuration'):
        load_config('nonsense')


def test_the_model_follows_the_config_file(tmp_path):
    """Change a length in a copy of cell.yaml: the URDF and the typed model follow it."""
    doc = yaml.safe_load((config_dir() / 'cell.yaml').read_text())
    doc['/**']['ros__parameters']['arm']['link_2_length'] = 1.2
    doc['/**']['ros__parameters']['robots']['scara_right']['base_xyz'] = [2.5, 2.0, 0.2]
    path = Path(tmp_path) / 'cell.yaml'
    path.write_text(yaml.safe_dump(doc))
    cell = load_cell(config=path)
    assert cell.leader.l2 == 1.2
    assert list(cell.follower.base_position) == [2.5, 2.0, 0.2]
    quill = parse_urdf(cell.urdf).joint_map['scara_left_gripper_joint']
    assert quill.origin[0, 3] == pytest.approx(1.2)
    assert load_cell().leader.l2 == 1.0
