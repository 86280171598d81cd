"""Message conversions refuse bad input at the door; entry points stay on localhost."""
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from scara_collab.core import moves
from scara_collab.core.mirror import mirror_joints
from scara_collab.core.move_time import stamp_time
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import runner


def test_non_finite_joint_states_are_refused(cell):
    """A joint state with NaN or infinity is refused; a finite one reads back."""
    names = list(cell.leader.joint_names) + list(cell.follower.joint_names)
    q = [0.0, 1.5708, 0.0] + list(mirror_joints(np.array([0.0, 1.5708, 0.0])))
    ok = conv.joint_state(1.0, names, q, [0.0] * 6, [0.0] * 6)
    pos, _ = conv.joint_state_arrays(ok, cell.leader.joint_names)
    np.testing.assert_allclose(pos, q[:3])
    for bad in (float('nan'), float('inf')):
        msg = conv.joint_state(1.0, names, q[:1] + [bad] + q[2:], [0.0] * 6, [0.0] * 6)
        with pytest.raises(conv.MessageError, match='non-finite'):
            conv.joint_state_arrays(msg, cell.leader.joint_names)


def test_absurdly_long_trajectories_are_refused(cell):
    """A trajectory beyond ``MAX_TRAJECTORY_POINTS`` is refused; a short one reads back."""
    arm = cell.leader
    n = conv.MAX_TRAJECTORY_POINTS + 1
    t = np.arange(n) * 0.01
    msg = conv.trajectory_msg(arm.joint_names, t, np.zeros((n, 3)))
    with pytest.raises(conv.MessageError, match=f'{n} points; at most'):
        conv.trajectory_arrays(msg, arm.joint_names)
    short = conv.trajectory_msg(arm.joint_names, t[:5], np.zeros((5, 3)))
    assert conv.trajectory_arrays(short, arm.joint_names)[1].shape == (5,)


def test_a_move_id_is_its_request_stamp_exactly():
    """A move id carries its request stamp's nanoseconds exactly; a bad id is refused."""
    ns = 133_510_992_676
    stamp = conv.time_from_ns(ns)
    assert conv.request_id(stamp) == ns
    assert moves.parse_move_id(moves.move_id('scara_left', ns)) == ('scara_left', ns)
    with pytest.raises(moves.MoveIdError):
        moves.parse_move_id('scara_left/not-a-number')


def test_every_entry_point_keeps_discovery_on_this_host(monkeypatch):
    """Every entry point keeps discovery on LOCALHOST unless the user chose a range."""
    monkeypatch.delenv(runner.DISCOVERY_ENV, raising=False)
    seen = {}

    def factory():
        import os
        seen['range'] = os.environ.get(runner.DISCOVERY_ENV)
        raise KeyboardInterrupt  # stop at once: run_node shuts down cleanly
    runner.run_node(factory, args=[])
    assert seen['range'] == 'LOCALHOST'
    monkeypatch.setenv(runner.DISCOVERY_ENV, 'SUBNET')  # the user's choice wins
    runner.run_node(factory, args=[])
    assert seen['range'] == 'SUBNET'


def test_stamp_gate_lets_through_only_the_sim_clocks_states():
    """The stamp gate lets through only finite, ordered stamps on the sim clock."""
    gate = conv.StampGate(tolerance=1.0)
    assert gate.check(0.01, 0.0) is None                 # before /clock: early stamps only
    assert 'before any /clock' in gate.check(5.0, 0.0)
    assert gate.check(10.0, 10.0) is None
    assert gate.check(10.5, 10.2) is None                # within the tolerance
    assert 'from the sim clock' in gate.check(1.79e9, 10.2)
    assert 'older than the last' in gate.check(10.1, 10.2)
    assert 'non-finite' in gate.check(float('nan'), 10.2)
    assert gate.check(10.5, None) is None                # off sim time: order only
    assert gate.refused == 4 and gate.last == 10.5


def test_target_frames_are_world_or_the_arms_base():
    """World and the arm's base (also as ``_base_link``) are understood; others refused."""
    assert conv.target_frame('world', 'scara_left') == 'world'
    assert conv.target_frame('scara_left_base', 'scara_left') == 'base'
    assert conv.target_frame('scara_left_base_link', 'scara_left') == 'base'
    for frame in ('', 'map', 'scara_right_base'):
        with pytest.raises(conv.MessageError, match='use world or scara_left_base'):
            conv.target_frame(frame, 'scara_left')


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=0.0, max_value=1e5, allow_nan=False))
def test_the_core_reads_a_start_as_its_stamp_says_it(t):
    """``move_time.stamp_time`` is what a stamp made by ``to_time`` reads back as, to the bit."""
    assert stamp_time(t) == conv.to_sec(conv.to_time(t))


def test_a_target_in_an_unknown_frame_reads_back_with_the_reason(cell):
    """``target_of`` gives the frame to plan in, or '' and why: the planner refuses it so."""
    xyz = np.array([1.0, 2.0, 0.5])
    xyz_back, stamp, frame, error = conv.target_of(
        conv.make_point_stamped(xyz, 'scara_left_base'), 'scara_left')
    np.testing.assert_array_equal(xyz_back, xyz)
    assert (frame, error) == ('base', '')
    assert conv.target_of(conv.make_point_stamped(xyz, 'map'), 'scara_left')[2:] == (
        '', "unknown frame 'map'; use world or scara_left_base")


def test_an_offer_reads_back_or_gives_its_stamp_and_the_reason(cell):
    """A good offer reads back as its arrays; a malformed one as its stamp and the reason."""
    arm = cell.leader
    t, q = np.array([0.0, 0.5]), np.array([[0.0, 1.0, 0.0], [0.1, 1.1, 0.0]])
    (stamp, t_back, q_back, _, _), error = conv.offer_of(
        conv.trajectory_msg(arm.joint_names, t, q, start=2.5), arm.joint_names)
    assert (stamp, error) == (2.5, '')
    np.testing.assert_array_equal(q_back, q)
    bad = conv.trajectory_msg(arm.joint_names, t, q * np.nan, start=2.5)
    arrays, error = conv.offer_of(bad, arm.joint_names)
    assert arrays == (2.5,) and 'non-finite' in error


def test_a_planners_move_and_hold_become_the_trajectories_it_sends(cell):
    """A move is named by its request and starts at its plan's start; a hold is one point now."""
    from scara_collab.core.arm_planner import HoldArm, SendMove
    from scara_collab.core.planning import Plan
    from scara_collab.core.trajectory import Trajectory
    arm = cell.leader
    t, q = np.array([0.0, 0.5]), np.array([[0.0, 1.0, 0.0], [0.1, 1.1, 0.0]])
    traj = Trajectory(t, q, np.zeros_like(q), np.zeros_like(q), np.zeros_like(q))
    msg = conv.move_msg(arm.name, arm.joint_names, SendMove(1500000000, Plan(traj, 3.0, 0.0)))
    assert msg.header.frame_id == 'scara_left/1500000000'
    stamp, t_back, q_back, _, _ = conv.trajectory_arrays(msg, arm.joint_names)
    assert stamp == 3.0
    np.testing.assert_array_equal(q_back, q)
    np.testing.assert_array_equal(t_back, t)
    hold = conv.move_msg(arm.name, arm.joint_names, HoldArm(q[1]))
    assert hold.header.frame_id == 'scara_left/hold'
    assert conv.trajectory_arrays(hold, arm.joint_names)[0] == 0.0
    np.testing.assert_array_equal(conv.trajectory_arrays(hold, arm.joint_names)[2], [q[1]])


def _reference_joint_state_arrays(msg, names):
    """Return what ``joint_state_arrays`` returned with numpy (before its plain-float path)."""
    index = {n: i for i, n in enumerate(msg.name)}
    missing = [n for n in names if n not in index]
    if missing:
        raise conv.MessageError(f'joint_states lacks {missing}')
    if len(msg.position) != len(msg.name):
        raise conv.MessageError('joint_states: position and name lengths differ')
    idx = [index[n] for n in names]
    pos = np.asarray(msg.position, dtype=float)[idx]
    vel = (np.asarray(msg.velocity, dtype=float)[idx] if len(msg.velocity) == len(msg.name)
           else np.zeros(len(names)))
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))):
        raise conv.MessageError(f'joint_states: non-finite position or velocity of {list(names)}')
    return pos, vel


def test_joint_state_arrays_equals_the_numpy_reference_on_good_and_bad_states():
    """Random states, good and malformed: the same arrays to the bit, or the same error."""
    from sensor_msgs.msg import JointState
    rng = np.random.default_rng(7)
    pool = [f'j{k}' for k in range(6)]
    outcomes = set()
    for _ in range(3000):
        n = int(rng.integers(0, 8))
        msg = JointState()
        msg.name = [pool[int(k)] for k in rng.integers(0, 6, size=n)]  # repeats, gaps
        values = rng.normal(size=(2, max(0, n + int(rng.choice([0, 0, 0, -1, 1])))))
        if values.size and rng.random() < 0.2:
            values.flat[int(rng.integers(values.size))] = rng.choice([np.nan, np.inf, -np.inf])
        msg.position = values[0].tolist()
        msg.velocity = values[1].tolist() if rng.random() < 0.8 else []
        names = [pool[int(k)] for k in rng.integers(0, 6, size=3)]
        try:
            want = _reference_joint_state_arrays(msg, names)
        except conv.MessageError as exc:
            with pytest.raises(conv.MessageError) as got:
                conv.joint_state_arrays(msg, names)
            assert str(got.value) == str(exc)
            outcomes.add(str(exc).split(' ')[1])
            continue
        got = conv.joint_state_arrays(msg, names)
        assert all(np.array_equal(g, w) and g.dtype == w.dtype for g, w in zip(got, want))
        outcomes.add('ok')
    assert outcomes == {'ok', 'lacks', 'position', 'non-finite'}


def test_a_scan_reads_back_only_with_its_scanners_geometry():
    """The ranges as floats, NaN and inf kept; another count, angle or limit is refused."""
    from sensor_msgs.msg import LaserScan

    from scara_collab.core.config import load_config
    from scara_collab.core.scan_tracking import scanners_from_config
    geometry = scanners_from_config(load_config('people'))[0]
    ranges = np.full(geometry.count, np.inf)
    ranges[:2] = [np.nan, 1.5]

    def scan(**changes):
        fields = dict(angle_min=geometry.angle_min, angle_increment=geometry.angle_increment,
                      range_min=geometry.range_min, range_max=geometry.range_max,
                      ranges=ranges.tolist())
        fields.update(changes)
        return LaserScan(**fields)
    out = conv.scan_ranges(scan(), geometry)
    assert out.dtype == float and np.isnan(out[0]) and out[1] == np.float32(1.5)
    assert np.all(np.isinf(out[2:]))
    for changes, text in (({'ranges': [1.0] * 3}, '3 rays'),
                          ({'angle_min': 0.0}, 'angle_min'),
                          ({'angle_increment': geometry.angle_increment * 2}, 'angle_increment'),
                          ({'range_max': 10.0}, 'range_max')):
        with pytest.raises(conv.MessageError, match=text):
            conv.scan_ranges(scan(**changes), geometry)
