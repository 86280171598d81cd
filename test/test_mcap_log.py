"""MCAP recording of a run: schema texts, a short in-process run read back two ways, cut files.

The run: the bridge (unthrottled, items fed) and the launcher's run recorder with a
:class:`McapRecorder` attached, in one executor; the probe moves the left arm and publishes the
three target topics. The file is read back with mcap + mcap_ros2's decoder (the ``ros2msg``
schemas stored in it) and by deserializing the raw bytes with rclpy against the real classes.
"""
from pathlib import Path
import subprocess
import sys

from geometry_msgs.msg import PointStamped
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import Graph, params_args
from rosbags.interfaces import QosDurability, QosHistory
from rosbags.rosbag2 import Reader as BagReader
from rosbags.typesys import get_typestore, Stores
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from tf_listener import by_child, pose_in
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core.kinematics import fk
from scara_collab.core.trajectory import joint_move
from scara_collab.graph import message_class, topics
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.mcap_recorder import McapRecorder
from scara_collab.nodes.pybullet_bridge import PyBulletBridge
from scara_collab.nodes.recorder import RunRecorder
from scara_collab.records.mcap_log import (
    iter_messages, msg_file, Reading, ros2msg_definition, SEPARATOR, type_hash)
from scara_collab.records.transforms import TF_HASH, TOPICS as DERIVED

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ('scara_left', 'scara_right')
TARGETS = {'/scara_left/target': (3.0, -0.8, 0.4), '/scara_right/target': (3.0, 0.8, 0.4),
           '/collab/target': (2.5, -0.6, 0.35)}
STATE_PERIOD = 0.01  # s, the bridge's joint states (config/simulation.yaml state_rate)


def _bridge(g: Graph, feed_interval: float = 0.0) -> PyBulletBridge:
    return g.add(PyBulletBridge(context=g.context, cli_args=params_args(
        'simulation', 'controllers',
        overrides={'real_time_factor': 0.0, 'feed_interval': feed_interval})))


def record_run(directory: Path, cell, seconds: float = 3.0) -> dict:
    """Record a short run into ``directory`` (timeseries.csv, events.csv, run.mcap, ...).

    The left arm makes a joint move; the three target topics get one message each; the probe
    logs a line (``/rosout``).

    :return: ``{'summary', 'targets': {topic: msg}, 'trajectory': msg, 'mcap': path}``.
    """
    g = Graph()
    try:
        bridge = _bridge(g, feed_interval=0.4)
        rec = g.add(RunRecorder(directory, 'collaborative', cell=cell, context=g.context))
        log = McapRecorder(rec, directory / 'run.mcap', robots=ROBOTS, urdf=cell.urdf)
        rec.sinks.append(log)
        assert g.spin_until(lambda: rec.log.t_last is not None and rec.sim_time > 0.2, 30)
        rec.start_job()
        arm = cell.leader
        q0 = bridge.sim.arm_state(arm.name)[0]
        move = joint_move(arm, q0, q0 + np.array([0.6, -0.5, 0.15]))
        traj = conv.trajectory_msg(arm.joint_names, move.t, move.q, move.qd, move.qdd)
        pubs = {name: g.probe.create_publisher(PointStamped, name, 10) for name in TARGETS}
        pubs['traj'] = g.probe.create_publisher(JointTrajectory, f'/{arm.name}/joint_trajectory',
                                                10)
        assert g.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
        pubs.pop('traj').publish(traj)
        targets = {}
        for name, xyz in TARGETS.items():
            targets[name] = conv.make_point_stamped(xyz, 'world', rec.sim_time + 0.5)
            pubs[name].publish(targets[name])
        assert g.spin_until(lambda: g.probe.count_subscribers('/rosout') > 0)
        g.probe.get_logger().info('record_run: targets sent')  # a /rosout line
        end = rec.job_start + seconds
        assert g.spin_until(lambda: rec.sim_time > end and all(
            log.counts[n] for n in (*TARGETS, '/rosout')), timeout=40)
        summary = rec.finish('test', False, plots=False)
        assert log.closed and summary['mcap']['file'] == 'run.mcap'
    finally:
        g.close()
    return {'summary': summary, 'targets': targets, 'trajectory': traj,
            'mcap': directory / 'run.mcap'}


@pytest.fixture(scope='module')
def recorded(tmp_path_factory, cell):
    """Record a short run once for the module; return what :func:`record_run` returns."""
    return record_run(tmp_path_factory.mktemp('mcap_run'), cell)


def read_all(path: Path):
    """Every message of the file, decoded by mcap_ros2: ``[(schema, channel, msg, decoded)]``."""
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        out = list(reader.iter_decoded_messages(log_time_order=False))
    return header, summary, out


# --- schemas ---------------------------------------------------------------------------------
def test_schema_text_is_the_main_msg_then_every_nested_type():
    """The schema text is the main .msg, then every nested type in rosbag2's order.

    An unknown type is refused.
    """
    text = ros2msg_definition('geometry_msgs/msg/PointStamped')

    def block(name, msg):
        return f'\n{SEPARATOR}\nMSG: {name}\n' + msg_file(msg).read_text()

    # rosbag2's order: the dependencies of each file sorted, depth first, each type once
    expected = (msg_file('geometry_msgs/msg/PointStamped').read_text()
                + block('geometry_msgs/Point', 'geometry_msgs/msg/Point')
                + block('std_msgs/Header', 'std_msgs/msg/Header')
                + block('builtin_interfaces/Time', 'builtin_interfaces/msg/Time'))
    assert text == expected
    assert 'std_msgs/Header header' in text and 'float64 x' in text
    path = ros2msg_definition('nav_msgs/msg/Path')
    names = [ln[5:] for ln in path.splitlines() if ln.startswith('MSG: ')]
    assert names == ['geometry_msgs/PoseStamped', 'geometry_msgs/Pose', 'geometry_msgs/Point',
                     'geometry_msgs/Quaternion', 'std_msgs/Header', 'builtin_interfaces/Time']
    with pytest.raises(FileNotFoundError, match='NoSuchType'):
        ros2msg_definition('std_msgs/msg/NoSuchType')


@pytest.mark.parametrize('topic', topics(ROBOTS), ids=lambda t: t.name)
def test_every_schema_parses_with_mcap_ros2_and_decodes_real_bytes(topic):
    """Every recorded topic's schema parses with mcap_ros2 and decodes a message's bytes."""
    schema = Schema(id=1, name=topic.type, encoding='ros2msg',
                    data=ros2msg_definition(topic.type).encode())
    decode = DecoderFactory().decoder_for('cdr', schema)
    assert decode is not None
    msg = message_class(topic.type)()
    decoded = decode(serialize_message(msg))  # a default message, through the stored schema
    assert list(decoded.__slots__) == list(msg.get_fields_and_field_types())


# --- a recorded run --------------------------------------------------------------------------
def test_the_recorded_run_reads_back_with_types_and_sim_timestamps(recorded):
    """The recorded run reads back with its types, in CDR, on sim log times.

    Log times never go backwards; mcap_ros2 and rclpy agree; the targets are as sent.
    """
    header, summary, messages = read_all(recorded['mcap'])
    assert header.profile == 'ros2'
    assert summary is not None and summary.statistics.message_count == len(messages)
    assert len(messages) == recorded['summary']['mcap']['messages']
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert types['/clock'] == 'rosgraph_msgs/msg/Clock'
    assert types['/joint_states'] == 'sensor_msgs/msg/JointState'
    assert types['/conveyor/items'] == 'visualization_msgs/msg/MarkerArray'
    for name in TARGETS:
        assert types[name] == 'geometry_msgs/msg/PointStamped'
    assert types['/scara_left/joint_trajectory'] == 'trajectory_msgs/msg/JointTrajectory'
    assert types['/scara_left/planned_path'] == 'nav_msgs/msg/Path'
    assert all(c.message_encoding == 'cdr' for c in summary.channels.values())
    assert all(s.encoding == 'ros2msg' for s in summary.schemas.values())

    log_times = np.array([m.log_time for _, _, m, _ in messages])
    assert np.all(np.diff(log_times) >= 0), 'log times never go backwards (file order)'
    by_topic = {}
    for schema, channel, msg, decoded in messages:
        by_topic.setdefault(channel.topic, []).append((msg, decoded))
    assert {'/clock', '/joint_states', '/conveyor/items', *TARGETS} <= set(by_topic)

    # /joint_states: mcap_ros2 and rclpy agree; sim stamps increase; log time = stamp
    states = by_topic['/joint_states']
    assert len(states) > 200
    stamps, lags = [], []
    for msg, decoded in states:
        real = deserialize_message(msg.data, JointState)
        assert list(real.name) == list(decoded.name) and len(real.name) == 6
        np.testing.assert_array_equal(real.position, decoded.position)
        assert (real.header.stamp.sec, real.header.stamp.nanosec) == (
            decoded.header.stamp.sec, decoded.header.stamp.nanosec)
        stamp = conv.to_sec(real.header.stamp)
        stamps.append(stamp)
        lags.append(msg.log_time * 1e-9 - stamp)
        assert msg.publish_time == msg.log_time
    assert np.all(np.diff(stamps) > 0)
    lags = np.array(lags[5:])  # the first states may come before the recorder's first tick
    print(f'\njoint_states log time - stamp: median {np.median(lags) * 1e3:.1f} ms, '
          f'range {lags.min() * 1e3:.1f}..{lags.max() * 1e3:.1f} ms')
    assert np.all(np.abs(lags) <= 3 * STATE_PERIOD + 1e-9), 'log time is the sim receive time'
    assert abs(np.median(lags)) <= STATE_PERIOD + 1e-9

    # /clock: the tick's own time
    clocks = by_topic['/clock']
    ticks = np.array([conv.to_sec(deserialize_message(m.data, Clock).clock) for m, _ in clocks])
    assert np.all(np.diff(ticks) > 0)
    decoded_ticks = [conv.to_sec(d.clock) for _, d in clocks]
    np.testing.assert_array_equal(decoded_ticks, ticks)
    clock_lag = np.array([m.log_time * 1e-9 for m, _ in clocks]) - ticks
    assert np.all(clock_lag >= -1e-9) and np.median(clock_lag) <= 1e-9

    # the targets as published (the bytes' CDR padding is arbitrary: compare the fields)
    for name, sent in recorded['targets'].items():
        (msg, decoded), = by_topic[name]
        assert len(msg.data) == len(serialize_message(sent))
        real = deserialize_message(msg.data, PointStamped)
        assert real == sent and decoded.point.x == sent.point.x
        assert decoded.header.frame_id == 'world'
        assert abs(msg.log_time * 1e-9 - (conv.to_sec(sent.header.stamp) - 0.5)) < 0.1
    (msg, _), = by_topic['/scara_left/joint_trajectory']
    assert deserialize_message(msg.data, JointTrajectory) == recorded['trajectory']

    items = [deserialize_message(m.data, MarkerArray) for m, _ in by_topic['/conveyor/items']]
    cubes = [mk for arr in items for mk in arr.markers if mk.type == Marker.CUBE]
    assert cubes and {mk.ns for mk in cubes} <= {'red', 'blue'}


def test_the_run_folder_is_a_rosbag2_bag_that_rosbags_reads(recorded):
    """The rosbags reader opens the run folder as a rosbag2 (Jazzy) bag, reads every message.

    Topics, types and counts are the run summary's; the offered QoS is the publisher's
    (``/emergency_stop`` transient local, ``/clock`` volatile); ``/rosout`` is recorded; every
    message deserialises with rosbags' own Jazzy typestore; the MCAP file carries the
    ``rosbag2`` metadata record.
    """
    folder = recorded['mcap'].parent
    counts = recorded['summary']['mcap']['topics']
    store = get_typestore(Stores.ROS2_JAZZY)
    with BagReader(folder) as reader:
        assert reader.ros_distro == 'jazzy' and not reader.compression_mode
        assert reader.message_count == recorded['summary']['mcap']['messages']
        conns = {c.topic: c for c in reader.connections}
        assert set(conns) == {t.name for t in topics(ROBOTS)} | {'/tf', '/tf_static'}
        assert {n: c.msgcount for n, c in conns.items() if c.msgcount} == counts
        for name, conn in conns.items():
            assert conn.msgtype == message_class_type(name)
            assert conn.digest == (type_hash(conn.msgtype) or TF_HASH)
            assert conn.digest.startswith('RIHS01_')
        (estop,) = conns['/emergency_stop'].ext.offered_qos_profiles
        assert estop.durability == QosDurability.TRANSIENT_LOCAL and estop.depth == 1
        (clock,) = conns['/clock'].ext.offered_qos_profiles
        assert clock.durability == QosDurability.VOLATILE
        assert clock.history == QosHistory.KEEP_LAST and clock.depth == 10
        (rosout,) = conns['/rosout'].ext.offered_qos_profiles
        assert rosout.durability == QosDurability.TRANSIENT_LOCAL and rosout.depth == 1000
        lines = [store.deserialize_cdr(raw, conn.msgtype).msg
                 for conn, _, raw in reader.messages(connections=[conns['/rosout']])]
        assert 'record_run: targets sent' in lines
        seen = {}
        for conn, timestamp, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            assert type(msg).__name__ == conn.msgtype.replace('/', '__')
            seen[conn.topic] = seen.get(conn.topic, 0) + 1
        assert seen == counts
        sent = recorded['targets']['/collab/target']
        (_, _, raw), = reader.messages(connections=[conns['/collab/target']])
        assert store.deserialize_cdr(raw, 'geometry_msgs/msg/PointStamped').point.x == (
            sent.point.x)
    with open(recorded['mcap'], 'rb') as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert records['rosbag2']['ROS_DISTRO'] == 'jazzy'
    assert 'version: 9' in records['rosbag2']['serialized_metadata']


def message_class_type(name: str) -> str:
    """Return the type the graph (or the recorder's derived topics) gives the topic ``name``."""
    return next(t.type for t in list(topics(ROBOTS)) + list(DERIVED) if t.name == name)


def test_the_recording_shows_the_arms_moving_from_its_own_transforms(recorded, cell):
    """``/robot_description``, ``/tf_static`` and ``/tf`` are in every recording, made by it.

    Read back with rosbags (no tf2_msgs needed to write them): the description is the cell's
    URDF, the static tree holds the bases, the belt and the bins, and each ``/tf`` carries the
    pose of every arm joint for one recorded joint state: composed from ``world`` it puts each
    tool where FK of that state does, to 1e-9 m.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    with BagReader(recorded['mcap'].parent) as reader:
        conns = {c.topic: c for c in reader.connections}

        def read(topic):
            return [store.deserialize_cdr(raw, conns[topic].msgtype)
                    for _, _, raw in reader.messages(connections=[conns[topic]])]
        (description,) = read('/robot_description')
        assert description.data == cell.urdf
        (static,) = read('/tf_static')
        states, tfs = read('/joint_states'), read('/tf')
    tree = by_child(static.transforms)
    assert {f'{a.name}_base_link' for a in cell.arms} | {'conveyor'} <= set(tree)
    assert len(tfs) == len(states) > 100
    for state, tf in list(zip(states, tfs))[::25]:
        assert tf.transforms[0].header.stamp.sec == state.header.stamp.sec
        assert tf.transforms[0].header.stamp.nanosec == state.header.stamp.nanosec
        frames = dict(tree, **by_child(tf.transforms))
        positions = dict(zip(state.name, state.position))
        for arm in cell.arms:
            q = np.array([positions[n] for n in arm.joint_names])
            np.testing.assert_allclose(pose_in(frames, f'{arm.name}_quill')[:3, 3], fk(arm, q),
                                       atol=1e-9)


def test_read_mcap_script_summarises_and_dumps(recorded):
    """``read_mcap.py`` prints the summary and dumps the asked topics' messages."""
    proc = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'read_mcap.py'),
                           str(recorded['mcap']), '--dump', '1', '--topic', '/joint_states',
                           '--topic', '/collab/target'],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert "profile 'ros2'" in out and 'complete' in out
    n = recorded['summary']['mcap']['topics']['/joint_states']
    line = next(ln for ln in out.splitlines() if ln.startswith('/joint_states '))
    assert 'sensor_msgs/msg/JointState' in line and f' {n} ' in line
    assert 'scara_left_joint_1' in out and 'frame_id' in out
    assert f'x: {TARGETS["/collab/target"][0]:.9g}' in out


def test_an_unclosed_recording_keeps_its_chunks_and_close_completes_it(tmp_path):
    """An unclosed recording keeps its complete chunks; closing it completes the file.

    The closed file holds every message, the cut file's first.
    """
    path = tmp_path / 'cut.mcap'
    g = Graph()
    try:
        _bridge(g)
        node = g.add(Node('recorder', context=g.context, parameter_overrides=[
            Parameter('use_sim_time', Parameter.Type.BOOL, True)]))
        log = McapRecorder(node, path, robots=ROBOTS, chunk_size=16 * 1024)
        assert g.spin_until(lambda: log.messages >= 600, timeout=30)
        log.flush()  # what a killed run leaves: the chunks so far, no summary, no footer
        reading = Reading()
        cut = list(iter_messages(path, reading=reading))
        assert not reading.complete
        assert len(cut) >= log.messages - 200  # at most the open chunk (~16 KiB) is missing
        assert {m.topic for m in cut} >= {'/clock', '/joint_states'}
        assert all(m.type for m in cut)
        log.close()
        written = log.messages
    finally:
        g.close()
    reading = Reading()
    full = list(iter_messages(path, reading=reading))
    assert reading.complete and len(full) == written
    assert full[:len(cut)] == cut


def test_the_tf_schema_is_tf2_msgs_own_when_it_is_not_installed(monkeypatch):
    """Without tf2_msgs the recorder writes TFMessage's schema itself: the installed one's text.

    (Where tf2_msgs is built, its own concatenated definition is the reference; else the text
    must at least parse and encode a transform.)
    """
    from scara_collab.records import mcap_log
    from scara_collab.records.transforms import TF_TYPE
    real = mcap_log.ros2msg_definition

    def missing_tf2(type_name):
        if type_name.startswith('tf2_msgs/'):
            raise FileNotFoundError(type_name)
        return real(type_name)
    try:
        installed = real(TF_TYPE)
    except FileNotFoundError:
        installed = None
    monkeypatch.setattr(mcap_log, 'ros2msg_definition', missing_tf2)
    text = mcap_log._definition(TF_TYPE)
    if installed is not None:  # the same, but for the comments of the .msg file

        def fields(t):
            return [ln for ln in t.splitlines() if not ln.lstrip().startswith('#')]
        assert fields(text) == fields(installed)
    schema = Schema(id=1, name=TF_TYPE, encoding='ros2msg', data=text.encode())
    assert DecoderFactory().decoder_for('cdr', schema) is not None
