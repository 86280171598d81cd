"""The cell's transform tree from its URDF, without ROS: what robot_state_publisher computes.

Each URDF joint links its parent frame to its child frame by its origin followed by its motion:
a rotation of ``q`` about the axis (revolute), a translation of ``q`` along it (prismatic), or
nothing (fixed). Fixed joints give the static transforms (``/tf_static``), the others the
moving ones (``/tf``) for the joint positions of ``/joint_states``; composing them from
``world`` gives each link's pose, and the ``<robot>_quill`` frame's origin is the tool tip of
:func:`scara_collab.core.kinematics.fk`.

>>> from scara_collab.core.model import load_cell
>>> tree = Tree.of(load_cell().urdf)
>>> T = tree.pose('scara_left_quill', {'scara_left_joint_1': 0.0, 'scara_left_joint_2': 0.0,
...                                    'scara_left_gripper_joint': 0.0})
>>> T[:3, 3].round(6).tolist()        # base (2, -2, 0.2), links 1.5 + 1.0 along x, z 0.7
[4.5, -2.0, 0.7]
"""
from dataclasses import dataclass
from typing import Dict, List, Mapping, Tuple

import numpy as np

from scara_collab.core.model import parse_urdf

MOVING = ('revolute', 'continuous', 'prismatic')


@dataclass(frozen=True)
class Joint:
    """One URDF joint: ``parent`` to ``child`` by ``origin`` ``(4, 4)``, then its motion."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray

    def transform(self, q: float = 0.0) -> np.ndarray:
        """Return the parent-to-child transform ``(4, 4)`` at joint position ``q``."""
        motion = np.eye(4)
        if self.type in ('revolute', 'continuous'):
            motion[:3, :3] = rotation(self.axis, q)
        elif self.type == 'prismatic':
            motion[:3, 3] = self.axis * q
        return self.origin @ motion


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Return the rotation matrix ``(3, 3)`` of ``angle`` rad about the unit ``axis`` (Rodrigues).

    >>> rotation(np.array([0.0, 0.0, 1.0]), np.pi / 2).round(6).tolist()[0]
    [0.0, -1.0, 0.0]
    """
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def quaternion(r: np.ndarray) -> Tuple[float, float, float, float]:
    """Return the unit quaternion ``(x, y, z, w)`` of the rotation matrix ``r`` ``(3, 3)``.

    Shepperd's method: the largest of the four squared components is taken first, so it is
    accurate for every rotation.

    >>> [round(v, 6) for v in quaternion(rotation(np.array([0.0, 0.0, 1.0]), np.pi / 2))]
    [0.0, 0.0, 0.707107, 0.707107]
    """
    t = np.trace(r)
    i = int(np.argmax([t, r[0, 0], r[1, 1], r[2, 2]]))
    if i == 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4)
    elif i == 1:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = (s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s)
    elif i == 2:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = ((r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s)
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = ((r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s)
    sign = -1.0 if q[3] < 0 else 1.0  # w >= 0: one of the two equal quaternions
    return tuple(float(sign * v) for v in q)


@dataclass(frozen=True)
class Tree:
    """The joints of a URDF: the static and the moving transforms, and link poses."""

    joints: Tuple[Joint, ...]
    root: str

    @staticmethod
    def of(urdf_xml: str) -> 'Tree':
        """Return the tree of the URDF text ``urdf_xml`` (its root link is the root)."""
        urdf = parse_urdf(urdf_xml)
        joints = tuple(
            Joint(j.name, j.type, j.parent, j.child,
                  np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float),
                  np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float))
            for j in urdf.robot.joints)
        return Tree(joints, urdf.base_link)

    @property
    def moving_joints(self) -> List[str]:
        """Names of the joints that move (revolute, continuous, prismatic)."""
        return [j.name for j in self.joints if j.type in MOVING]

    def static(self) -> List[Tuple[str, str, np.ndarray]]:
        """Return ``(parent, child, transform)`` of every fixed joint."""
        return [(j.parent, j.child, j.transform()) for j in self.joints if j.type not in MOVING]

    def moving(self, positions: Mapping[str, float]) -> List[Tuple[str, str, np.ndarray]]:
        """Return ``(parent, child, transform)`` of every moving joint named in ``positions``."""
        return [(j.parent, j.child, j.transform(float(positions[j.name])))
                for j in self.joints if j.type in MOVING and j.name in positions]

    def pose(self, frame: str, positions: Mapping[str, float]) -> np.ndarray:
        """Return the pose ``(4, 4)`` of ``frame`` in the root frame (missing joints at 0).

        :raises KeyError: for a frame that is not in the tree.
        """
        by_child: Dict[str, Joint] = {j.child: j for j in self.joints}
        pose = np.eye(4)
        while frame != self.root:
            joint = by_child[frame]
            pose = joint.transform(float(positions.get(joint.name, 0.0))) @ pose
            frame = joint.parent
        return pose
