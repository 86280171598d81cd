"""The transform tree (core/frames): link poses against FK and against yourdfpy's own chain."""
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from tf_listener import matrix_of

from scara_collab.core.frames import quaternion, rotation, Tree
from scara_collab.core.kinematics import fk
from scara_collab.core.model import parse_urdf


@pytest.fixture(scope='module')
def tree(cell):
    """Return the cell's tree."""
    return Tree.of(cell.urdf)


def test_the_tool_frame_is_fk_and_every_link_is_the_urdfs_own(cell, tree):
    """``<robot>_quill`` in ``world`` is FK's tool tip; every link pose is yourdfpy's."""
    urdf = parse_urdf(cell.urdf)
    rng = np.random.default_rng(7)
    for _ in range(50):
        positions = {}
        for arm in cell.arms:
            positions.update(zip(arm.joint_names, rng.uniform(arm.lower, arm.upper)))
        urdf.update_cfg(positions)
        for arm in cell.arms:
            q = np.array([positions[n] for n in arm.joint_names])
            tip = tree.pose(f'{arm.name}_quill', positions)[:3, 3]
            np.testing.assert_allclose(tip, fk(arm, q), atol=1e-12)
        for joint in tree.joints:
            np.testing.assert_allclose(tree.pose(joint.child, positions),
                                       urdf.get_transform(joint.child, 'world'), atol=1e-12)


def test_static_and_moving_transforms_split_the_joints(cell, tree):
    """Fixed joints are static (bases, belt, bins); the six arm joints move."""
    static = {child for _, child, _ in tree.static()}
    assert {f'{a.name}_base_link' for a in cell.arms} <= static and 'conveyor' in static
    assert tree.moving_joints == [n for a in cell.arms for n in a.joint_names]
    positions = dict.fromkeys(tree.moving_joints, 0.3)
    moving = tree.moving(positions)
    assert len(moving) == 6 and all(t.shape == (4, 4) for _, _, t in moving)
    first = tree.moving({'scara_left_joint_1': 0.1})[0]
    assert first[:2] == ('scara_left_base_link', 'scara_left_link_1')


@settings(max_examples=200, deadline=None)
@given(st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3),
       st.floats(-np.pi, np.pi))
def test_quaternion_round_trip(axis, angle):
    """A rotation's quaternion is unit, has w >= 0 and gives the rotation back."""
    axis = np.asarray(axis) / np.linalg.norm(axis)
    r = rotation(axis, angle)
    q = quaternion(r)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12 and q[3] >= 0.0
    np.testing.assert_allclose(matrix_of(*q), r, atol=1e-12)
