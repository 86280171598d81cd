"""rosbag2 metadata: the offered QoS and metadata.yaml texts against hand-written YAML.

The expected texts are written out by hand in the layout of rosbag2 Jazzy's own files
(``rosbag2_tests/resources/mcap/*/metadata.yaml``, version 9 with named policies); rosbags,
an independent reader, parses the QoS back. A recorded run read as a bag is in
``test_mcap_log.py``.
"""
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2.metadata import parse_qos
from ruamel.yaml import YAML

from scara_collab import graph
from scara_collab.records import bag

LATCHED_YAML = """\
- history: keep_last
  depth: 1
  reliability: reliable
  durability: transient_local
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false"""


def test_the_latched_profile_serialises_as_rosbag2_writes_it():
    """The latched profile is rosbag2's version-9 YAML; rosbags reads it back as offered."""
    assert bag.qos_yaml([bag.offered_qos(graph.QOS['latched'])]) == LATCHED_YAML
    text = bag.qos_yaml(bag.topic_qos(graph.topic('/emergency_stop')))
    assert text == LATCHED_YAML
    (qos,) = parse_qos(text)
    assert qos.history == QosHistory.KEEP_LAST and qos.depth == 1
    assert qos.reliability == QosReliability.RELIABLE
    assert qos.durability == QosDurability.TRANSIENT_LOCAL


def test_volatile_profiles_and_rosout():
    """Other graph topics are volatile with their depth; /rosout is rcl's profile."""
    clock = bag.topic_qos(graph.topic('/clock'))
    assert clock == [dict(bag.offered_qos(graph.QOS['default']))]
    assert clock[0]['durability'] == 'volatile' and clock[0]['depth'] == 10
    events = bag.topic_qos(graph.topic('/conveyor/events'))[0]
    assert events['depth'] == 100
    rosout = bag.topic_qos(graph.topic('/rosout'))
    assert bag.qos_yaml(rosout) == LATCHED_YAML.replace('depth: 1\n', 'depth: 1000\n').replace(
        'lifespan:\n    sec: 9223372036\n    nsec: 854775807',
        'lifespan:\n    sec: 10\n    nsec: 0')


def test_to_yaml_quotes_what_yaml_would_read_otherwise():
    """Empty strings, booleans-as-text and numbers-as-text are quoted; empty maps are ``~``."""
    text = bag.to_yaml({'a': '', 'b': 'true', 'c': '12', 'd': 'x y', 'e': {}, 'f': [],
                        'g': '/rosout', 'h': None})
    assert text == ('a: ""\nb: "true"\nc: "12"\nd: "x y"\ne: ~\nf: []\ng: /rosout\nh: ~')


def test_metadata_yaml_is_rosbag2_jazzy_layout():
    """A hand-checked metadata.yaml: the exact text, which YAML reads back as written."""
    topics = [bag.TopicRecord(graph.topic('/emergency_stop'), 'RIHS01_ab', 2)]
    meta = bag.bag_metadata(topics, 'run.mcap', 1_000_000_000, 500, {'mode': 'single'})
    text = bag.metadata_yaml(meta)
    indented = '\n'.join('          ' + ln for ln in LATCHED_YAML.splitlines())
    expected = f"""\
rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: 500
  starting_time:
    nanoseconds_since_epoch: 1000000000
  message_count: 2
  topics_with_message_count:
    - topic_metadata:
        name: /emergency_stop
        type: std_msgs/msg/Bool
        serialization_format: cdr
        offered_qos_profiles:
{indented}
        type_description_hash: RIHS01_ab
      message_count: 2
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - run.mcap
  files:
    - path: run.mcap
      starting_time:
        nanoseconds_since_epoch: 1000000000
      duration:
        nanoseconds: 500
      message_count: 2
  custom_data:
    mode: single
  ros_distro: jazzy
"""
    assert text == expected
    # a YAML parser (rosbags' own, ruamel) reads back exactly the metadata written
    assert YAML(typ='safe').load(text) == {'rosbag2_bagfile_information': meta}
    assert YAML(typ='safe').load(bag.to_yaml(meta)) == meta  # the MCAP record's text
