"""The robot model: the URDF's own chain against the SPEC geometry, profiles, mass properties."""
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.model import expand_xacro, load_cell, parse_urdf

# SPEC section 1, typed in here on purpose: the model must reproduce these numbers.
L1, L2 = 1.5, 1.0
BASES = {'scara_left': (2.0, -2.0, 0.2), 'scara_right': (2.0, 2.0, 0.2)}
LIMIT = np.deg2rad(150.0)
THICKNESS = {'slim': 0.05, 'default': 0.10, 'heavy': 0.15}


def spec_tool(base, q):
    """Tool tip in world from the SPEC's convention (theta1 = 0 along +x, tip z = 0.7 - d3)."""
    t1, t2, d3 = q
    return np.array([base[0] + L1 * np.cos(t1) + L2 * np.cos(t1 + t2),
                     base[1] + L1 * np.sin(t1) + L2 * np.sin(t1 + t2),
                     0.7 - d3])


@pytest.mark.parametrize('robot', sorted(BASES))
def test_urdf_chain_puts_the_tool_where_the_spec_says(cell, robot):
    """The cell URDF's chain puts the tool, elbow and link 1 where the SPEC says."""
    urdf = parse_urdf(cell.urdf)
    arm = cell.arm(robot)
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.uniform(arm.lower, arm.upper)
        urdf.update_cfg(dict(zip(arm.joint_names, q)))
        tip = urdf.get_transform(f'{robot}_quill', 'world')[:3, 3]
        assert_allclose(tip, spec_tool(BASES[robot], q), atol=1e-9)
        elbow = urdf.get_transform(f'{robot}_link_2', 'world')[:3, 3]
        assert_allclose(elbow[:2], np.array(BASES[robot][:2]) + L1 * np.array(
            [np.cos(q[0]), np.sin(q[0])]), atol=1e-9)
        assert elbow[2] == pytest.approx(0.7)
        assert urdf.get_transform(f'{robot}_link_1', 'world')[2, 3] == pytest.approx(0.6)


def test_typed_model_matches_spec(cell):
    """The typed model has the SPEC's names, lengths, bases, limits, reach, margin and belt."""
    assert [a.name for a in cell.arms] == ['scara_left', 'scara_right']
    for arm in cell.arms:
        assert arm.joint_names == (f'{arm.name}_joint_1', f'{arm.name}_joint_2',
                                   f'{arm.name}_gripper_joint')
        assert (arm.l1, arm.l2) == (L1, L2)
        assert_allclose(arm.base_position, BASES[arm.name])
        assert_allclose(arm.base[:3, :3], np.eye(3))
        assert_allclose(arm.lower, [-LIMIT, -LIMIT, 0.0], atol=1e-3)
        assert_allclose(arm.upper, [LIMIT, LIMIT, 0.6], atol=1e-3)
        assert_allclose(arm.max_velocity[:2], 2.0)
        assert arm.base_position[2] + arm.tool_z0 == pytest.approx(0.7)
    assert (cell.reach_min, cell.reach_max) == (0.55, 2.45)
    assert cell.safety_margin == 0.10
    assert cell.belt.speed == 0.2 and cell.belt.width == 1.0 and cell.belt.top_z == 0.2


@pytest.mark.parametrize('profile', sorted(THICKNESS))
def test_profiles_set_thickness_and_mass_from_density(profile):
    """Each profile sets the link radius; masses and inertias follow from the density."""
    cell = load_cell(profile)
    rho = load_config('cell')['arm']['link_density']
    r = THICKNESS[profile] / 2
    for arm in cell.arms:
        assert arm.link_radius == pytest.approx(r)
        assert arm.link_1.mass == pytest.approx(rho * np.pi * r ** 2 * L1)
        assert arm.link_2.mass == pytest.approx(rho * np.pi * r ** 2 * L2)
        # a uniform rod about its centre, about the vertical axis: m (3 r^2 + L^2) / 12
        assert arm.link_1.inertia[2, 2] == pytest.approx(
            arm.link_1.mass * (3 * r ** 2 + L1 ** 2) / 12)
        assert_allclose(arm.link_1.com, [L1 / 2, 0, 0])
        assert_allclose(arm.link_2.com, [L2 / 2, 0, 0])


def test_profiles_differ_as_specified():
    """Link mass grows with the cross-section (1 : 4 : 9) across the profiles."""
    slim, default, heavy = (load_cell(p).leader for p in ('slim', 'default', 'heavy'))
    # mass goes with the cross-section: (0.05 : 0.10 : 0.15)^2 = 1 : 4 : 9
    assert default.link_1.mass / slim.link_1.mass == pytest.approx(4.0)
    assert heavy.link_1.mass / slim.link_1.mass == pytest.approx(9.0)
    assert slim.link_radius < default.link_radius < heavy.link_radius
    assert slim.l1 == default.l1 == heavy.l1


@pytest.mark.parametrize('profile', sorted(THICKNESS))
def test_inertias_are_physically_valid(profile):
    """Every inertia is physically valid and no mass or inertia is a placeholder.

    Symmetric, positive definite and within the triangle inequality.
    """
    for arm in load_cell(profile).arms:
        for link in (arm.link_1, arm.link_2, arm.quill):
            inertia = link.inertia
            assert_allclose(inertia, inertia.T)
            eig = np.linalg.eigvalsh(inertia)
            assert np.all(eig > 0), 'inertia must be positive definite'
            a, b, c = eig
            assert a + b >= c - 1e-12 and a + c >= b - 1e-12 and b + c >= a - 1e-12
            assert link.mass > 0.1, 'no placeholder masses'
            assert not np.allclose(np.diag(inertia), 0.001), 'no placeholder inertias'


def test_bins_sit_on_each_arms_outer_side_within_reach(cell):
    """Each arm's bins are on its outer side within its reach, mirrored across the belt."""
    for arm in cell.arms:
        base = arm.base_position
        for cls in cell.item_classes:
            b = cell.bins[(arm.name, cls)]
            assert abs(b[1] - cell.belt.centre_y) > abs(base[1] - cell.belt.centre_y)
            r = np.hypot(*(b[:2] - base[:2]))
            assert cell.reach_min < r < cell.reach_max
    left = [cell.bins[('scara_left', c)] for c in cell.item_classes]
    right = [cell.bins[('scara_right', c)] for c in cell.item_classes]
    for bl, br in zip(left, right):  # mirror images across the belt
        assert_allclose(bl * [1, -1, 1], br)


def test_single_arm_xacro_matches_the_cell():
    """The single-arm xacro has the same joint origins and link masses as the cell URDF."""
    for robot in BASES:
        arm = parse_urdf(expand_xacro('scara_arm.urdf.xacro', robot=robot, profile='heavy'))
        cell = parse_urdf(load_cell('heavy').urdf)
        for j in (f'{robot}_joint_1', f'{robot}_joint_2', f'{robot}_gripper_joint'):
            assert_allclose(arm.joint_map[j].origin, cell.joint_map[j].origin)
        assert arm.link_map[f'{robot}_link_1'].inertial.mass == pytest.approx(
            cell.link_map[f'{robot}_link_1'].inertial.mass)
