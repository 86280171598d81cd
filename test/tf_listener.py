"""A TF listener written for the tests, independent of scara_collab.core.frames.

Not a test module (no ``test_`` prefix): the TF tests import it. It reads any
``TransformStamped``-shaped objects (rclpy messages or rosbags' decoded ones).
"""
from typing import Dict, Iterable

import numpy as np


def matrix_of(x, y, z, w) -> np.ndarray:
    """Return the rotation matrix of a unit quaternion (the textbook formula, written here)."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def by_child(transforms: Iterable) -> Dict[str, object]:
    """Return the transforms by child frame, the last of each."""
    return {t.child_frame_id: t for t in transforms}


def pose_in(frames: Dict[str, object], frame: str, root: str = 'world') -> np.ndarray:
    """Return the pose ``(4, 4)`` of ``frame`` in ``root``, composed along ``frames``' parents."""
    pose = np.eye(4)
    while frame != root:
        t = frames[frame]
        step = np.eye(4)
        r, p = t.transform.rotation, t.transform.translation
        step[:3, :3] = matrix_of(r.x, r.y, r.z, r.w)
        step[:3, 3] = [p.x, p.y, p.z]
        pose, frame = step @ pose, t.header.frame_id
    return pose
