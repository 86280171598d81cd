"""The robot model, from one source: ``config/cell.yaml`` -> xacro -> URDF -> typed description.

The xacro files compute every mass, centre of mass and inertia from the link geometry and the
material densities in the config. This module expands them with the xacro Python API, parses
the URDF with yourdfpy and reads back what the kinematics, dynamics and simulator need. Nothing
downstream reads link lengths or masses from anywhere else.

Example::

    >>> cell = load_cell()
    >>> left = cell.leader
    >>> left.l1, left.l2, left.joint_names[2]
    (1.5, 1.0, 'scara_left_gripper_joint')
"""
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
import io
from pathlib import Path
from typing import Dict, Optional, Tuple, Union

import numpy as np
import xacro
import yourdfpy

from scara_collab.core.config import ConfigError, load_config
from scara_collab.core.paths import config_dir, urdf_dir


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class LinkInertia:
    """Mass properties of one link, in that link's frame.

    :ivar mass: kg.
    :ivar com: (3,) centre of mass, m.
    :ivar inertia: (3, 3) inertia tensor about the centre of mass, kg m^2.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class ArmModel:
    """One SCARA arm as the URDF describes it.

    Joint order everywhere in the package: ``(theta1, theta2, d3)``.

    :ivar name: robot name and namespace, e.g. ``scara_left``.
    :ivar joint_names: ``(<name>_joint_1, <name>_joint_2, <name>_gripper_joint)``.
    :ivar base: (4, 4) homogeneous pose of the base frame in ``world``.
    :ivar l1: shoulder-to-elbow length, m.
    :ivar l2: elbow-to-quill length, m.
    :ivar shoulder_height: shoulder frame above the base frame, m.
    :ivar elbow_rise: link 2 frame above link 1 frame, m.
    :ivar lower, upper: (3,) joint position limits (rad, rad, m).
    :ivar max_velocity, max_acceleration, max_effort: (3,) joint limits.
    :ivar viscous, coulomb: (3,) joint friction coefficients.
    :ivar link_1, link_2, quill: mass properties of the moving links.
    :ivar link_radius: radius of the link cylinders (half the profile thickness), m.
    :ivar quill_radius, quill_length: the quill rod, m (it rises from the tool tip).
    :ivar reach_min, reach_max: allowed tool distance from the shoulder axis, m (the geometric
        annulus |L1 - L2| .. L1 + L2 shrunk by the cell's safety epsilon).
    """

    name: str
    joint_names: Tuple[str, str, str]
    base: np.ndarray
    l1: float
    l2: float
    shoulder_height: float
    elbow_rise: float
    lower: np.ndarray
    upper: np.ndarray
    max_velocity: np.ndarray
    max_acceleration: np.ndarray
    max_effort: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    link_1: LinkInertia
    link_2: LinkInertia
    quill: LinkInertia
    link_radius: float
    quill_radius: float
    quill_length: float
    reach_min: float
    reach_max: float

    @property
    def base_position(self) -> np.ndarray:
        """Base frame origin in ``world``, (3,)."""
        return self.base[:3, 3]

    @property
    def tool_z0(self) -> float:
        """Tool tip height in the base frame at ``d3 = 0``, m."""
        return self.shoulder_height + self.elbow_rise

    @cached_property
    def constants(self) -> Tuple[float, ...]:
        """Plain-float copies for scalar hot paths (IK in a few microseconds).

        ``(l1, l2, tool_z0, reach_min, reach_max, R00, R01, R02, R10, R11, R12, R20, R21, R22,
        bx, by, bz, lo1, hi1, lo2, hi2, lo3, hi3)``: lengths, reach window, base rotation
        (row-major), base origin and the joint position limits.
        """
        return (self.l1, self.l2, self.tool_z0, self.reach_min, self.reach_max,
                *map(float, self.base[:3, :3].ravel()),
                *map(float, self.base[:3, 3]),
                *(float(v) for pair in zip(self.lower, self.upper) for v in pair))

    @property
    def moving_mass(self) -> float:
        """Mass carried by the shoulder: link 1, link 2 and the quill, kg."""
        return self.link_1.mass + self.link_2.mass + self.quill.mass


@dataclass(frozen=True)
class BeltModel:
    """The conveyor belt.

    Items move along +x at ``speed`` on a belt of ``width`` around ``centre_y``, from
    ``x_start`` to ``x_end``; the belt's top face is at ``top_z``.
    """

    speed: float
    width: float
    centre_y: float
    x_start: float
    x_end: float
    top_z: float


@dataclass(frozen=True)
class CellModel:
    """Both arms, the belt, the bins and the rules of the cell.

    :ivar arms: the arms, leader first (the leader has priority).
    :ivar profile: link profile the model was built with.
    :ivar urdf: the expanded cell URDF (XML string), as the simulator loads it.
    :ivar reach_min, reach_max: reach window from the shoulder axis, with the safety epsilon.
    :ivar safety_margin: required distance between the arms' capsule surfaces, m.
    :ivar bins: ``{(robot, item_class): (3,) bin floor centre in world}``.
    :ivar item_classes: the two item classes.
    :ivar item_size, item_mass: cube edge (m) and mass (kg) of a sorted item.
    :ivar config: the validated ``cell.yaml`` parameters the model came from.
    """

    arms: Tuple[ArmModel, ArmModel]
    profile: str
    urdf: str = field(repr=False)
    reach_min: float
    reach_max: float
    safety_margin: float
    belt: BeltModel
    bins: Dict[Tuple[str, str], np.ndarray]
    item_classes: Tuple[str, str]
    item_size: float
    item_mass: float
    config: dict = field(repr=False)

    @property
    def leader(self) -> ArmModel:
        """The priority arm (``scara_left`` by default)."""
        return self.arms[0]

    @property
    def follower(self) -> ArmModel:
        """The arm that mirrors the leader and yields to it."""
        return self.arms[1]

    def arm(self, name: str) -> ArmModel:
        """Return the arm called ``name``.

        :raises KeyError: with the known names, if there is none.
        """
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f'no arm {name!r}; the cell has {[a.name for a in self.arms]}')


def expand_xacro(filename: str = 'scara_cell.urdf.xacro', **args: str) -> str:
    """Expand one of the package's xacro files and return the URDF XML.

    :param filename: a file of ``urdf/`` (``scara_cell.urdf.xacro`` or
        ``scara_arm.urdf.xacro``).
    :param args: xacro arguments, e.g. ``profile='slim'``, ``robot='scara_right'``,
        ``config='/path/cell.yaml'``.
    """
    doc = xacro.process_file(str(urdf_dir() / filename),
                             mappings={k: str(v) for k, v in args.items()})
    return doc.toprettyxml(indent='  ')


def parse_urdf(xml: str) -> yourdfpy.URDF:
    """Parse URDF XML with yourdfpy (no meshes are loaded: the model is primitives only)."""
    return yourdfpy.URDF.load(io.StringIO(xml), build_scene_graph=True, load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)


def _link_inertia(urdf: yourdfpy.URDF, link: str) -> LinkInertia:
    inertial = urdf.link_map[link].inertial
    if inertial is None or inertial.mass is None:
        raise ConfigError(f'URDF link {link!r} has no inertial block')
    origin = np.eye(4) if inertial.origin is None else np.asarray(inertial.origin)
    rot = origin[:3, :3]
    inertia = rot @ np.asarray(inertial.inertia, dtype=float) @ rot.T
    return LinkInertia(float(inertial.mass), _frozen(origin[:3, 3]), _frozen(inertia))


def _cylinder(urdf: yourdfpy.URDF, link: str):
    geom = urdf.link_map[link].collisions[0].geometry.cylinder
    return float(geom.radius), float(geom.length)


def _arm_from_urdf(urdf: yourdfpy.URDF, name: str, acceleration: np.ndarray,
                   reach: Tuple[float, float]) -> ArmModel:
    jn = (f'{name}_joint_1', f'{name}_joint_2', f'{name}_gripper_joint')
    joints = [urdf.joint_map[j] for j in jn]
    base = np.asarray(urdf.joint_map[f'{name}_base_joint'].origin, dtype=float)
    j1, j2, j3 = (np.asarray(j.origin, dtype=float) for j in joints)
    link_radius, _ = _cylinder(urdf, f'{name}_link_1')
    quill_radius, quill_length = _cylinder(urdf, f'{name}_quill')
    return ArmModel(
        name=name,
        joint_names=jn,
        base=_frozen(base),
        l1=float(j2[0, 3]),
        l2=float(j3[0, 3]),
        shoulder_height=float(j1[2, 3]),
        elbow_rise=float(j2[2, 3]),
        lower=_frozen([j.limit.lower for j in joints]),
        upper=_frozen([j.limit.upper for j in joints]),
        max_velocity=_frozen([j.limit.velocity for j in joints]),
        max_acceleration=_frozen(acceleration),
        max_effort=_frozen([j.limit.effort for j in joints]),
        viscous=_frozen([(j.dynamics.damping if j.dynamics else None) or 0.0 for j in joints]),
        coulomb=_frozen([(j.dynamics.friction if j.dynamics else None) or 0.0 for j in joints]),
        link_1=_link_inertia(urdf, f'{name}_link_1'),
        link_2=_link_inertia(urdf, f'{name}_link_2'),
        quill=_link_inertia(urdf, f'{name}_quill'),
        link_radius=link_radius,
        quill_radius=quill_radius,
        quill_length=quill_length,
        reach_min=float(reach[0]),
        reach_max=float(reach[1]),
    )


@lru_cache(maxsize=16)
def _load_cell(profile: Optional[str], config_path: str) -> CellModel:
    cfg = load_config('cell', config_path)
    profile = profile or cfg['arm']['profile']
    if profile not in cfg['profiles']:
        raise ConfigError(
            f'unknown profile {profile!r}; expected one of {sorted(cfg["profiles"])}')
    xml = expand_xacro('scara_cell.urdf.xacro', profile=profile, config=config_path)
    urdf = parse_urdf(xml)
    lim = cfg['joints']
    acc = [lim['revolute_acceleration'], lim['revolute_acceleration'], lim['quill_acceleration']]
    names = tuple(cfg['robots']['names'])
    reach = (cfg['reach']['min_radius'], cfg['reach']['max_radius'])
    arms = tuple(_arm_from_urdf(urdf, n, acc, reach) for n in names)
    classes = tuple(cfg['items']['classes'])
    bins = {(n, c): _frozen(np.asarray(urdf.joint_map[f'{n}_bin_{c}_joint'].origin)[:3, 3])
            for n in names for c in classes}
    belt = BeltModel(**{k: float(cfg['belt'][k]) for k in
                        ('speed', 'width', 'centre_y', 'x_start', 'x_end', 'top_z')})
    return CellModel(
        arms=arms, profile=profile, urdf=xml,
        reach_min=float(cfg['reach']['min_radius']),
        reach_max=float(cfg['reach']['max_radius']),
        safety_margin=float(cfg['collision']['safety_margin']),
        belt=belt, bins=bins, item_classes=classes,
        item_size=float(cfg['items']['size']), item_mass=float(cfg['items']['mass']),
        config=cfg)


def load_cell(profile: Optional[str] = None,
              config: Optional[Union[str, Path]] = None) -> CellModel:
    """Build the cell model from the config and the xacro files.

    Results are cached per ``(profile, config)``; the returned model is immutable.

    :param profile: ``slim``, ``default`` or ``heavy``; default: ``arm.profile`` of the config.
    :param config: path of a ``cell.yaml``; default: the package's ``config/cell.yaml``.
    :raises ConfigError: for an invalid config or unknown profile.
    """
    path = Path(config) if config is not None else config_dir() / 'cell.yaml'
    return _load_cell(profile, str(path.resolve()))
