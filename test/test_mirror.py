"""Mirroring across the belt: the design documents' example, involution, joint-space sameness."""
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from numpy.testing import assert_allclose

from scara_collab.core.kinematics import fk, ik
from scara_collab.core.mirror import mirror_error, mirror_joints, mirror_point
from scara_collab.core.model import load_cell

CELL = load_cell()
LEFT, RIGHT = CELL.leader, CELL.follower
coord = st.floats(-5, 5, allow_nan=False)


def test_the_design_documents_case_study_3():
    """Check the design documents' case study 3 against the SPEC formula.

    The case study moves "forward 1 m from the left base" and expects the right arm 1 m
    forward from its base, (2, 1). Forward (towards the belt) from (2, -2) is (2, -1); the
    printed input (2, -3) is 1 m *backwards*, and the SPEC's formula mirrors it to (2, 3).
    """
    assert_allclose(mirror_point(LEFT, RIGHT, [2.0, -1.0, 0.3]), [2.0, 1.0, 0.3])
    assert_allclose(mirror_point(LEFT, RIGHT, [2.0, -3.0, 0.3]), [2.0, 3.0, 0.3])
    # P_R = B_R + diag(1, -1)(P_L - B_L), z unchanged
    p = np.array([3.1, -0.4, 0.25])
    expected = RIGHT.base_position + np.array([1, -1, 1]) * (p - LEFT.base_position)
    assert_allclose(mirror_point(LEFT, RIGHT, p), expected)
    assert mirror_point(LEFT, RIGHT, p)[2] == p[2]


@settings(max_examples=200, deadline=None)
@given(st.tuples(coord, coord, coord))
def test_mirroring_twice_is_the_identity(p):
    """Mirroring a point there and back, or joints twice, is the identity (hypothesis)."""
    p = np.array(p)
    assert_allclose(mirror_point(RIGHT, LEFT, mirror_point(LEFT, RIGHT, p)), p, atol=1e-12)
    assert_allclose(mirror_joints(mirror_joints(p)), p)


def test_joint_mirror_equals_point_mirror():
    """The joint mirror maps through FK to the point mirror.

    IK of a mirrored target from the mirrored state gives the mirrored joints.
    """
    rng = np.random.default_rng(8)
    q = rng.uniform(LEFT.lower, LEFT.upper, (1000, 3))
    assert_allclose(fk(RIGHT, mirror_joints(q)), mirror_point(LEFT, RIGHT, fk(LEFT, q)),
                    atol=1e-12)
    # and IK of the mirrored target, from the mirrored state, is the mirrored solution
    p = fk(LEFT, q)
    sol = ik(RIGHT, mirror_point(LEFT, RIGHT, p), q_current=mirror_joints(q))
    ok = sol.ok
    assert ok.mean() > 0.5
    assert_allclose(sol.q[ok], mirror_joints(q)[ok], atol=1e-9)


def test_mirror_of_a_belt_point_is_across_the_belt():
    """A point on the left half of the belt mirrors to the same x on the right half."""
    p = np.array([2.5, -0.3, 0.3])  # on the left half of the belt
    m = mirror_point(LEFT, RIGHT, p)
    assert_allclose(m, [2.5, 0.3, 0.3])


def test_mirror_error_is_zero_for_mirrored_joints_and_the_offset_otherwise():
    """Mirrored joint states have no mirror error; a follower tool off by d has error |d|."""
    rng = np.random.default_rng(9)
    q = rng.uniform(LEFT.lower, LEFT.upper, (500, 3))
    p_left, p_right = fk(LEFT, q), fk(RIGHT, mirror_joints(q))
    assert_allclose(mirror_error(LEFT, RIGHT, p_left, p_right), 0.0, atol=1e-12)
    offset = rng.normal(size=(500, 3))
    err = mirror_error(LEFT, RIGHT, p_left, p_right + offset)
    assert err.shape == (500,)
    assert_allclose(err, np.linalg.norm(offset, axis=1), rtol=1e-12)
    assert mirror_error(LEFT, RIGHT, p_left[0], p_right[0] + [0.0, 0.0, 0.1]).shape == ()


def test_joint_mirroring_is_exact_only_for_arms_of_the_same_geometry():
    """The cell's arms mirror joint by joint; an arm with a longer link 2 does not."""
    from dataclasses import replace
    from scara_collab.core.mirror import is_joint_mirror
    assert is_joint_mirror(LEFT, RIGHT) and is_joint_mirror(RIGHT, LEFT)
    assert not is_joint_mirror(LEFT, replace(RIGHT, l2=RIGHT.l2 + 0.1))
