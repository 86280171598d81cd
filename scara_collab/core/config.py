"""Load and validate the cell's ``config/*.yaml`` files.

The files are ROS 2 parameter files (``/**: ros__parameters: {...}``) so that nodes load them
with ``--ros-args --params-file``; this module reads the same files for the layers that have no
ROS. Every value the code uses is checked here, once, with an error that names the file, the key
and what was wrong.

Example::

    >>> cfg = load_config('cell')
    >>> cfg['arm']['link_1_length']
    1.5
"""
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Callable, Iterable, Optional, Union

import yaml

from scara_collab.core.paths import config_dir

CONFIG_NAMES = ('cell', 'simulation', 'controllers', 'automation', 'people')


class ConfigError(ValueError):
    """A configuration file is missing, malformed, or holds an invalid value."""


@dataclass(frozen=True)
class Rule:
    """One checked key: dotted ``key``, expected ``kind``, and an optional value check."""

    key: str
    kind: str  # 'number', 'positive', 'nonneg', 'int', 'bool', 'str', 'text', 'vec3', 'list'
    check: Optional[Callable[[Any], bool]] = None
    why: str = ''


def _num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


_KINDS = {
    'number': (_num, 'a finite number'),
    'positive': (lambda v: _num(v) and v > 0, 'a number > 0'),
    'nonneg': (lambda v: _num(v) and v >= 0, 'a number >= 0'),
    'int': (lambda v: isinstance(v, int) and not isinstance(v, bool), 'an integer'),
    'bool': (lambda v: isinstance(v, bool), 'true or false'),
    'str': (lambda v: isinstance(v, str) and v != '', 'a non-empty string'),
    'text': (lambda v: isinstance(v, str), 'a string'),
    'vec3': (lambda v: isinstance(v, list) and len(v) == 3 and all(_num(x) for x in v),
             'a list of 3 finite numbers'),
    'list': (lambda v: isinstance(v, list) and len(v) > 0, 'a non-empty list'),
}

_GAINS = ('kp', 'ki', 'kd')


def _interval(v) -> bool:
    """Return True for ``[low, high]`` with ``0 <= low <= high`` (finite numbers)."""
    return len(v) == 2 and all(_num(x) for x in v) and 0 <= v[0] <= v[1]


SCHEMAS = {
    'cell': [
        Rule('arm.link_1_length', 'positive'),
        Rule('arm.link_2_length', 'positive'),
        Rule('arm.shoulder_height', 'positive'),
        Rule('arm.elbow_rise', 'nonneg'),
        Rule('arm.profile', 'str'),
        Rule('arm.link_density', 'positive'),
        Rule('arm.quill_radius', 'positive'),
        Rule('arm.quill_length', 'positive'),
        Rule('arm.quill_density', 'positive'),
        Rule('arm.quill_travel', 'positive'),
        Rule('arm.base_radius', 'positive'),
        Rule('joints.revolute_limit', 'positive', lambda v: v <= math.pi, 'must be <= pi'),
        Rule('joints.revolute_velocity', 'positive'),
        Rule('joints.revolute_acceleration', 'positive'),
        Rule('joints.shoulder_effort', 'positive'),
        Rule('joints.elbow_effort', 'positive'),
        Rule('joints.quill_velocity', 'positive'),
        Rule('joints.quill_acceleration', 'positive'),
        Rule('joints.quill_effort', 'positive'),
        Rule('joints.revolute_damping', 'nonneg'),
        Rule('joints.revolute_friction', 'nonneg'),
        Rule('joints.quill_damping', 'nonneg'),
        Rule('joints.quill_friction', 'nonneg'),
        Rule('robots.names', 'list', lambda v: len(v) == 2 and len(set(v)) == 2,
             'must name exactly two distinct robots (leader first)'),
        Rule('reach.min_radius', 'nonneg'),
        Rule('reach.max_radius', 'positive'),
        Rule('belt.speed', 'nonneg'),
        Rule('belt.width', 'positive'),
        Rule('belt.centre_y', 'number'),
        Rule('belt.x_start', 'number'),
        Rule('belt.x_end', 'number'),
        Rule('belt.top_z', 'number'),
        Rule('collision.safety_margin', 'nonneg'),
        Rule('items.size', 'positive'),
        Rule('items.mass', 'positive'),
        Rule('items.classes', 'list', lambda v: len(v) == 2 and len(set(v)) == 2,
             'must name exactly two distinct item classes'),
        Rule('bins.size', 'vec3', lambda v: all(x > 0 for x in v), 'sizes must be > 0'),
        Rule('bins.outward_offset', 'positive'),
        Rule('bins.class_x_offsets', 'list', lambda v: all(_num(x) for x in v),
             'must be numbers'),
    ],
    'simulation': [
        Rule('physics_rate', 'positive', lambda v: 100 <= v <= 10000,
             'must be in [100, 10000] Hz'),
        Rule('solver_iterations', 'int', lambda v: v >= 1, 'must be >= 1'),
        Rule('gravity', 'vec3'),
        Rule('real_time_factor', 'nonneg'),
        Rule('state_rate', 'positive'),
        Rule('clock_rate', 'positive'),
        Rule('gui', 'bool'),
        Rule('servo_rate', 'positive'),
        Rule('friction_smoothing', 'positive'),
        Rule('velocity_tolerance', 'nonneg', lambda v: v <= 0.1, 'must be <= 0.1 (10 %)'),
        Rule('start_tolerance', 'positive'),
        Rule('item_rate', 'positive'),
        Rule('item_seed', 'int'),
        Rule('feed_interval', 'nonneg'),
        Rule('feed_pattern', 'str', lambda v: v in ('random', 'mirror_pairs'),
             "must be 'random' or 'mirror_pairs'"),
        Rule('lateral_jitter', 'nonneg'),
        Rule('inlet_margin', 'nonneg'),
        Rule('rest_speed', 'positive'),
        Rule('grasp_tolerance', 'positive'),
    ],
    'controllers': [
        Rule('control_mode', 'str', lambda v: v in ('pid', 'computed_torque'),
             "must be 'pid' or 'computed_torque'"),
        *[Rule(f'pid.{g}.{k}', 'nonneg') for g in ('planar', 'quill') for k in _GAINS],
        *[Rule(f'computed_torque.{g}.{k}', 'positive')
          for g in ('planar', 'quill') for k in ('kp', 'kd')],
        Rule('planning_buffer', 'nonneg'),
        Rule('planning_lead', 'positive'),
        Rule('admission_allowance', 'number'),
        Rule('trajectory.sample_period', 'positive', lambda v: v <= 0.1, 'must be <= 0.1 s'),
        Rule('trajectory.dls_threshold', 'positive'),
        Rule('trajectory.dls_max_damping', 'nonneg'),
        Rule('trajectory.offer_tolerance', 'positive'),
    ],
    'automation': [
        Rule('mode', 'str', lambda v: v in ('single', 'collaborative', 'mirrored'),
             "must be 'single', 'collaborative' or 'mirrored'"),
        Rule('pick_clearance', 'nonneg'),
        Rule('grasp_reach', 'positive'),
        Rule('lift_after_grasp', 'bool'),
        Rule('carry_clearance', 'nonneg'),
        Rule('drop_clearance', 'nonneg'),
        Rule('mirror_pair_offset', 'nonneg'),
        Rule('mirror_start_lead', 'positive'),
        Rule('decision_lead', 'positive'),
        Rule('answer_timeout', 'positive'),
        Rule('answer_retries', 'int', lambda v: v >= 0, 'must be >= 0'),
        Rule('move_timeout', 'positive'),
        Rule('carry_timeout', 'positive'),
        Rule('unblock_after', 'positive'),
        Rule('arrive_timeout', 'positive'),
        Rule('arrive_tolerance', 'positive'),
        Rule('grip_timeout', 'positive'),
        Rule('grip_retries', 'int', lambda v: v >= 0, 'must be >= 0'),
        Rule('line_cells', 'int', lambda v: v >= 1, 'must be >= 1'),
        Rule('line_cell', 'int', lambda v: v >= 0, 'must be >= 0'),
        Rule('line_capacity', 'positive'),
        Rule('person_speed', 'number', lambda v: 0.0 <= v <= 1.0, 'must be in [0, 1]'),
        Rule('person_buffer', 'nonneg'),
        Rule('person_least_speed', 'number', lambda v: 0.0 <= v <= 1.0, 'must be in [0, 1]'),
    ],
    'people': [
        Rule('person.scenario', 'str'),
        Rule('person.seed', 'int'),
        Rule('person.walking_speed', 'positive'),
        Rule('person.reach_speed', 'positive'),
        Rule('person.turn_rate', 'positive'),
        *[Rule(f'person.body.{k}', 'positive') for k in (
            'leg_radius', 'hip_height', 'stance', 'step_amplitude', 'step_length',
            'torso_radius', 'torso_length', 'shoulder_offset', 'head_radius', 'neck',
            'arm_radius', 'reach')],
        Rule('person.work.reach_pitch', 'number', lambda v: 0 <= v < math.pi / 2,
             'must be in [0, pi/2) rad'),
        Rule('person.work.lean', 'nonneg', lambda v: v < math.pi / 4, 'must be < pi/4 rad'),
        Rule('person.work.hold', 'nonneg'),
        Rule('person.work.rest', 'nonneg'),
        Rule('person.random.mean_interval', 'positive'),
        Rule('person.random.dwell', 'list', _interval, 'must be [low, high], 0 <= low <= high'),
        Rule('person.random.speed', 'list', lambda v: _interval(v) and v[0] > 0,
             'must be [low, high], 0 < low <= high'),
        Rule('person.random.horizon', 'positive'),
        Rule('person.floor', 'list', lambda v: len(v) == 4 and all(_num(x) for x in v)
             and v[0] < v[1] and v[2] < v[3], 'must be [x_min, x_max, y_min, y_max]'),
        Rule('person.earliest', 'nonneg'),
        Rule('scanner.height', 'positive', lambda v: v <= 1.0,
             'must be <= 1.0 m (ISO 13855 horizontal fields)'),
        Rule('scanner.rate', 'positive'),
        Rule('scanner.names', 'list', lambda v: all(isinstance(n, str) and n for n in v)
             and len(set(v)) == len(v), 'must be distinct names'),
        Rule('scanner.field_of_view', 'positive', lambda v: v <= 2 * math.pi,
             'must be <= 2 pi rad'),
        Rule('scanner.rays', 'int', lambda v: v >= 2, 'must be >= 2'),
        Rule('scanner.range_min', 'nonneg'),
        Rule('scanner.range_max', 'positive'),
        Rule('scanner.noise', 'nonneg'),
        Rule('scanner.ghost_probability', 'nonneg', lambda v: v <= 1.0, 'must be <= 1'),
        Rule('scanner.seed', 'int'),
        Rule('monitor.walking_speed', 'positive'),
        Rule('monitor.reach_speed', 'positive'),
        Rule('monitor.reach_limit', 'nonneg'),
        Rule('monitor.reaction.scanner', 'nonneg'),
        Rule('monitor.reaction.monitor', 'nonneg'),
        Rule('monitor.reaction.bridge', 'nonneg'),
        Rule('monitor.sensor_tolerance', 'nonneg'),
        Rule('monitor.robot_tolerance', 'nonneg'),
        Rule('monitor.stop_allowance', 'number', lambda v: v >= 1.0, 'must be >= 1'),
        Rule('monitor.foreground', 'positive'),
        Rule('monitor.teach_scans', 'int', lambda v: v >= 1, 'must be >= 1'),
        Rule('monitor.cluster_gap', 'positive'),
        Rule('monitor.min_points', 'int', lambda v: v >= 1, 'must be >= 1'),
        Rule('monitor.body_margin', 'nonneg'),
        Rule('monitor.column_height', 'positive'),
        Rule('monitor.mute_margin', 'nonneg'),
        Rule('monitor.self_filter_radius', 'nonneg'),
        Rule('monitor.stale_after', 'positive'),
        Rule('monitor.track_gate', 'positive'),
        Rule('monitor.track_hold', 'nonneg'),
        Rule('monitor.velocity_window', 'positive'),
        Rule('monitor.hysteresis', 'nonneg'),
        Rule('monitor.dwell', 'nonneg'),
        Rule('monitor.resume_rate', 'positive'),
    ],
}


def _get(tree: dict, dotted: str):
    node = tree
    for part in dotted.split('.'):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(dotted)
        node = node[part]
    return node


def _check_cell(cfg: dict, where: str) -> None:
    """Cross-field checks of the cell file."""
    def fail(msg):
        raise ConfigError(f'{where}: {msg}')

    arm = cfg['arm']
    profiles = cfg.get('profiles')
    if not isinstance(profiles, dict) or not profiles:
        fail('profiles must map profile names to {link_thickness: ...}')
    for name, prof in profiles.items():
        t = prof.get('link_thickness') if isinstance(prof, dict) else None
        if not (_num(t) and 0 < t < min(arm['link_1_length'], arm['link_2_length'])):
            fail(f'profiles.{name}.link_thickness must be a number in (0, link length), got {t!r}')
    if arm['profile'] not in profiles:
        fail(f"arm.profile {arm['profile']!r} is not one of {sorted(profiles)}")
    l1, l2 = arm['link_1_length'], arm['link_2_length']
    lo, hi = cfg['reach']['min_radius'], cfg['reach']['max_radius']
    if not abs(l1 - l2) <= lo < hi <= l1 + l2:
        fail(f'reach must satisfy |L1-L2| <= min_radius < max_radius <= L1+L2, got '
             f'{lo} and {hi} with L1={l1}, L2={l2}')
    for name in cfg['robots']['names']:
        pose = cfg['robots'].get(name)
        if not isinstance(pose, dict):
            fail(f'robots.{name} must give base_xyz and base_rpy')
        for k in ('base_xyz', 'base_rpy'):
            if not _KINDS['vec3'][0](pose.get(k)):
                fail(f'robots.{name}.{k} must be a list of 3 finite numbers, got {pose.get(k)!r}')
    if cfg['belt']['x_end'] <= cfg['belt']['x_start']:
        fail('belt.x_end must be greater than belt.x_start')
    if len(cfg['bins']['class_x_offsets']) != len(cfg['items']['classes']):
        fail('bins.class_x_offsets needs one entry per item class')


def _check_people(cfg: dict, where: str) -> None:
    """Cross-field checks of the people file."""
    def fail(msg):
        raise ConfigError(f'{where}: {msg}')

    scanner = cfg['scanner']
    for name in scanner['names']:
        pose = scanner.get(name)
        pose = pose.get('pose') if isinstance(pose, dict) else None
        if not (isinstance(pose, list) and len(pose) == 3 and all(_num(x) for x in pose)):
            fail(f'scanner.{name}.pose must be [x, y, yaw], got {pose!r}')
    if not scanner['range_min'] < scanner['range_max']:
        fail('scanner.range_min must be less than scanner.range_max')
    if cfg['person']['walking_speed'] > cfg['monitor']['walking_speed']:
        fail('person.walking_speed must not exceed monitor.walking_speed (the speed the '
             'monitor assumes)')
    if cfg['person']['reach_speed'] > cfg['monitor']['reach_speed']:
        fail('person.reach_speed must not exceed monitor.reach_speed')
    if cfg['person']['random']['speed'][1] > cfg['monitor']['walking_speed']:
        fail('person.random.speed must not exceed monitor.walking_speed')


def check_rules(rules: Iterable[Rule], values: dict, where: str) -> dict:
    """Check ``values`` against ``rules``; the first missing or invalid key raises.

    The checks of :func:`validate`, for any set of rules: also a node's own parameters.

    :param rules: the rules; a dotted key looks into nested dicts.
    :param values: the values (nested dicts).
    :param where: what the values are, for the error message (a file or a node).
    :return: ``values`` unchanged.
    :raises ConfigError: ``'<where>: <key> must be ..., got ...'``.

    >>> try:
    ...     check_rules([Rule('rate', 'positive')], {'rate': 0.0}, 'probe')
    ... except ConfigError as exc:
    ...     print(exc)
    probe: rate must be a number > 0, got 0.0
    """
    for rule in rules:
        try:
            value = _get(values, rule.key)
        except KeyError:
            raise ConfigError(f'{where}: missing required key {rule.key!r}') from None
        ok, what = _KINDS[rule.kind]
        if not ok(value):
            raise ConfigError(f'{where}: {rule.key} must be {what}, got {value!r}')
        if rule.check is not None and not rule.check(value):
            raise ConfigError(f'{where}: {rule.key} {rule.why}, got {value!r}')
    return values


def validate(name: str, cfg: Any, where: str = '') -> dict:
    """Check a ``ros__parameters`` dict against the schema of config file ``name``.

    :param name: one of :data:`CONFIG_NAMES`.
    :param cfg: the parameters (the content under ``ros__parameters``).
    :param where: file name for the error message.
    :return: ``cfg`` unchanged.
    :raises ConfigError: naming the first missing or invalid key.
    """
    where = where or f'{name}.yaml'
    if not isinstance(cfg, dict):
        raise ConfigError(f'{where}: expected a mapping of parameters, got {type(cfg).__name__}')
    check_rules(SCHEMAS[name], cfg, where)
    if name == 'cell':
        _check_cell(cfg, where)
    if name == 'people':
        _check_people(cfg, where)
    return cfg


def read_params_file(path: Union[str, Path]) -> dict:
    """Read a ROS 2 parameter file and return the ``/**`` (or only node's) parameters.

    :raises ConfigError: if the file is missing or not a parameter file.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f'{path}: no such configuration file') from None
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML: {exc}') from None
    if not isinstance(doc, dict) or not doc:
        raise ConfigError(f'{path}: expected "/**: ros__parameters: ..." at the top level')
    section = doc.get('/**', next(iter(doc.values())))
    if not isinstance(section, dict) or 'ros__parameters' not in section:
        raise ConfigError(f'{path}: expected "/**: ros__parameters: ..." at the top level')
    return section['ros__parameters']


def load_config(name: str, path: Optional[Union[str, Path]] = None) -> dict:
    """Load and validate one configuration file.

    :param name: one of :data:`CONFIG_NAMES`.
    :param path: file to read; default ``<config_dir>/<name>.yaml``.
    :return: the validated parameter tree (nested dicts).
    :raises ConfigError: if the file is missing or a value is invalid.
    """
    if name not in SCHEMAS:
        raise ConfigError(f'unknown configuration {name!r}; expected one of {CONFIG_NAMES}')
    path = Path(path) if path is not None else config_dir() / f'{name}.yaml'
    return validate(name, read_params_file(path), where=str(path))


def load_all(directory: Optional[Union[str, Path]] = None) -> dict:
    """Load every configuration file of a directory: ``{name: parameters}``."""
    directory = Path(directory) if directory is not None else config_dir()
    return {n: load_config(n, directory / f'{n}.yaml') for n in CONFIG_NAMES}
