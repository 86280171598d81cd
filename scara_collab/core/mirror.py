"""Leader-follower mirroring across the conveyor.

A leader target ``P_L`` (world) maps to the follower target
``P_R = B_R + diag(1, -1, 1) (P_L - B_L)``: the same move relative to each base, reflected
across the base's x axis, z unchanged (both bases at the same height). In joint space the
reflection negates both angles: ``(theta1, theta2, d3) -> (-theta1, -theta2, d3)``.

Example (the design documents' case study 3: "forward 1 m from the left base" is (2, -1),
which mirrors to (2, 1); the (2, -3) they print is 1 m *away* from the belt, and mirrors to
(2, 3))::

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> mirror_point(cell.leader, cell.follower, [2.0, -1.0, 0.3])
    array([2. , 1. , 0.3])
    >>> mirror_point(cell.leader, cell.follower, [2.0, -3.0, 0.3])
    array([2. , 3. , 0.3])
"""
from typing import Union

import numpy as np

from scara_collab.core.kinematics import base_to_world, fk, world_to_base
from scara_collab.core.model import ArmModel

ArrayLike = Union[np.ndarray, list, tuple]
_REFLECT = np.array([1.0, -1.0, 1.0])


def mirror_point(src: ArmModel, dst: ArmModel, p: ArrayLike) -> np.ndarray:
    """Mirror world point(s) ``(..., 3)`` relative to ``src``'s base onto ``dst``'s base.

    The reflection is taken in the base frames (so it also holds for rotated bases):
    ``p_dst_base = diag(1, -1, 1) p_src_base``. Applying it twice (src -> dst -> src) is the
    identity.
    """
    return base_to_world(dst, world_to_base(src, p) * _REFLECT)


def mirror_error(src: ArmModel, dst: ArmModel, p_src: ArrayLike, p_dst: ArrayLike) -> np.ndarray:
    """Distance of ``dst``'s tool from the mirror image of ``src``'s tool, m.

    :param src: the arm that is mirrored (the leader).
    :param dst: the arm that mirrors it (the follower).
    :param p_src: ``(..., 3)`` tool positions of ``src`` in world, m.
    :param p_dst: ``(..., 3)`` tool positions of ``dst`` in world, m (same leading shape).
    :return: ``(...)`` ``|p_dst - mirror_point(src, dst, p_src)|``, m.

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> mirror_error(cell.leader, cell.follower, [[2.0, -1.0, 0.3]], [[2.0, 1.0, 0.4]])
    array([0.1])
    """
    p_dst = np.asarray(p_dst, dtype=float)
    return np.linalg.norm(p_dst - mirror_point(src, dst, p_src), axis=-1)


def mirror_joints(q: ArrayLike) -> np.ndarray:
    """Joint-space mirror ``(..., 3)``: negate theta1 and theta2, keep d3.

    For two arms with the same geometry, ``fk(dst, mirror_joints(q)) ==
    mirror_point(src, dst, fk(src, q))``; elbow up maps to elbow down, which is the mirror
    image of the leader's posture.
    """
    q = np.asarray(q, dtype=float)
    return q * np.array([-1.0, -1.0, 1.0])


def is_joint_mirror(src: ArmModel, dst: ArmModel, samples: int = 16, tol: float = 1e-9) -> bool:
    """Return True if :func:`mirror_joints` mirrors ``src``'s tool onto ``dst``'s exactly.

    It does for two arms of the same geometry (the cell's, from one xacro macro): then a
    leader's trajectory mirrors to the follower's joint by joint. Checked over ``samples``
    poses spread over the joint ranges; if the arms differ, mirror their tool points instead.

    >>> from scara_collab.core.model import load_cell
    >>> cell = load_cell()
    >>> is_joint_mirror(cell.leader, cell.follower)
    True
    """
    u = (np.arange(samples)[:, None] * np.array([0.381966, 0.618034, 0.723607])) % 1.0
    q = src.lower + u * (src.upper - src.lower)
    err = fk(dst, mirror_joints(q)) - mirror_point(src, dst, fk(src, q))
    return bool(np.all(np.abs(err) <= tol))
