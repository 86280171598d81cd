"""The simulated person's body: capsules posed from the path, in PyBullet, contact detected."""
import time

import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.ssm import intrusion_distance
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.person import (
    arm_distance, arm_link_names, body_capsules, BodyModel, capsule_poses, PARKED, PersonSim,
    SEGMENTS)
from scara_collab.sim.person_scenarios import (
    Motion, PersonPath, scenario, scenario_from_dict)


@pytest.fixture(scope='module')
def cfg():
    """Return config/people.yaml."""
    return load_config('people')


@pytest.fixture(scope='module')
def body(cfg):
    """Return the body model."""
    return BodyModel.from_config(cfg)


@pytest.fixture(scope='module')
def sim():
    """Return a cell simulator (one per module)."""
    with CellSim() as s:
        yield s


def standing(cfg, x, y, face, work=True, dwell=30.0):
    """Return the path of a person standing at (x, y) from 2 s on, facing ``face``."""
    doc = {'visits': [{'start': 2.0, 'speed': 1.0, 'waypoints': [
        {'x': x, 'y': y, 'dwell': dwell, 'face': list(face), 'work': work}]}]}
    return PersonPath(scenario_from_dict(doc, 'stand', 1.0), Motion.from_config(cfg))


def inlet_states(cell, cfg):
    """Return the inlet scenario's states every 20 ms while the person is there."""
    path = PersonPath(scenario('inlet', cell, cfg), Motion.from_config(cfg))
    t = np.arange(path.times[0], path.end, 0.02)
    return path.state(t[path.present(t)])


def test_every_capsule_keeps_its_length_and_the_feet_the_floor(cell, cfg, body):
    """Posed anywhere on a scenario, each capsule has its length; the feet touch the floor."""
    caps = body_capsules(body, inlet_states(cell, cfg))
    assert caps.start.shape[1:] == (len(SEGMENTS), 3)
    assert_allclose(np.linalg.norm(caps.end - caps.start, axis=-1),
                    np.broadcast_to(body.lengths, caps.start.shape[:-1]), atol=1e-9)
    feet = np.minimum(caps.start[:, :2, 2], caps.end[:, :2, 2]) - body.leg_radius
    assert feet.min() >= -1e-9 and feet.max() <= 0.05
    head_top = caps.end[:, 3, 2] + body.head_radius
    assert head_top.max() == pytest.approx(1.76, abs=0.02)


def test_the_reach_is_covered_by_the_intrusion_distance(cell, cfg, body):
    """No part of the body gets farther from the legs' column than C (ISO 13855).

    What a floor scanner cannot see of a person (the arms, the lean), C covers. The column is
    what the monitor makes of the legs: centred between them, as wide as they stand plus the
    body margin.
    """
    states = inlet_states(cell, cfg)
    caps = body_capsules(body, states)
    centre = states[:, None, :2]
    column = body.stance + body.leg_radius + cfg['monitor']['body_margin']
    c = intrusion_distance(cfg['scanner']['height'])
    beyond = np.maximum(np.linalg.norm(caps.start[..., :2] - centre, axis=-1),
                        np.linalg.norm(caps.end[..., :2] - centre, axis=-1)) + body.radii
    assert beyond.max() - column <= c
    assert beyond[:, 5].max() > 0.8  # the hand does reach out


def test_a_pose_turns_z_onto_the_capsule_axis(cell, cfg, body):
    """Each pose is the capsule's centre, its quaternion turning z onto the capsule's axis."""
    caps = body_capsules(body, inlet_states(cell, cfg)[::50])
    poses = capsule_poses(caps)
    assert_allclose(poses[..., :3], 0.5 * (caps.start + caps.end))
    x, y, z, w = (poses[..., k] for k in range(3, 7))
    z_axis = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1)
    axis = caps.end - caps.start
    length = np.linalg.norm(axis, axis=-1, keepdims=True)
    has_axis = length[..., 0] > 0
    assert_allclose(z_axis[has_axis], (axis / np.where(length > 0, length, 1))[has_axis],
                    atol=1e-9)
    assert_allclose(np.linalg.norm(poses[..., 3:], axis=-1), 1.0)


def test_the_body_is_in_the_world_only_while_present(sim, cfg, body):
    """Before its visit the person is parked below the floor; then the rays meet its legs."""
    pb = sim.client
    person = PersonSim(pb, body, standing(cfg, -2.0, -5.0, (0.0, -5.0)), 0,
                       arm_link_names(pb, 0, sim.cell.arms))
    try:
        ray = ([-4.0, -4.9, 0.3], [0.0, -4.9, 0.3])  # through the left leg
        assert not person.update(1.0)
        assert pb.rayTestBatch([ray[0]], [ray[1]])[0][0] == -1
        assert person.update(3.0) and person.poses().shape == (6, 7)
        hit = pb.rayTestBatch([ray[0]], [ray[1]])[0]
        assert hit[0] in person.bodies
        assert person.update(40.0) is False  # gone
        assert person.capsules() is None and len(person.poses()) == 0
        assert pb.getBasePositionAndOrientation(person.bodies[0])[0] == pytest.approx(PARKED)
    finally:
        person.close()


def test_contact_with_an_arm_is_detected_and_does_not_push_it(sim, cfg, body):
    """A person standing in the left arm's way touches its links: detected, the arm unmoved.

    The analytic distance of the capsule model agrees with PyBullet's: the capsules are the
    URDF's cylinders with round ends, so never farther than them.
    """
    pb = sim.client
    q = np.array([0.0, 0.0, 0.3])  # stretched along +x at the shoulder's height
    sim.reset_arm('scara_left', q)
    person = PersonSim(pb, body, standing(cfg, 3.2, -2.0, (4.0, -2.0), work=False), 0,
                       arm_link_names(pb, 0, sim.cell.arms))
    try:
        person.update(3.0)
        caps = person.capsules()
        assert arm_distance(caps, sim.cell.leader, q) < 0.0
        touching = person.contacts()
        assert touching and {c.link for c in touching} <= {'scara_left_link_1',
                                                           'scara_left_link_2'}
        assert all(c.depth >= 0.0 for c in touching)
        sim.step(200)
        assert_allclose(sim.arm_state('scara_left')[0], q, atol=1e-3)
        far = standing(cfg, -3.0, -5.0, (0.0, -5.0), work=False)
        person.path = far
        person.update(3.0)
        assert person.contacts() == []
        gap = [p[8] for p in pb.getClosestPoints(person.bodies[2], 0, 10.0)
               if p[4] in person.arm_links]
        assert arm_distance(person.capsules(), sim.cell.leader, q) <= min(gap) + 1e-6
    finally:
        person.close()
        sim.reset_arm('scara_left', np.zeros(3))


def test_moving_the_person_is_cheap(sim, cfg, body):
    """Posing the body costs well under a millisecond (it runs at the scan or item rate)."""
    pb = sim.client
    person = PersonSim(pb, body, PersonPath(scenario('inlet', sim.cell, cfg),
                                            Motion.from_config(cfg)),
                       0, arm_link_names(pb, 0, sim.cell.arms))
    try:
        t0 = time.process_time()
        for k in range(500):
            person.update(5.0 + 0.01 * k)
        per = (time.process_time() - t0) / 500
        print(f'person update: {per * 1e3:.3f} ms')
        assert per < 1e-3
    finally:
        person.close()
