"""What makes a run folder a rosbag2 bag: offered QoS and bag metadata, as ROS 2 Jazzy has them.

rosbag2 (Jazzy, metadata version 9, storage plugin ``mcap``) keeps three things beside the
messages, all written by :class:`scara_collab.records.mcap_log.McapWriter`:

- per MCAP channel, the metadata ``offered_qos_profiles`` (the publisher's QoS as a YAML
  sequence, :func:`qos_yaml` of :func:`offered_qos`) and ``topic_type_hash`` (the REP-2011
  ``RIHS01_...`` hash of the type);
- an MCAP metadata record ``rosbag2`` whose ``serialized_metadata`` is the bag metadata
  (:func:`bag_metadata`) in YAML;
- ``metadata.yaml`` next to the ``.mcap`` file: the same under ``rosbag2_bagfile_information``
  (:func:`metadata_yaml`), which ``ros2 bag info/play`` and rosbags read first.

A profile is serialised as rosbag2 does from version 9 on: policies by name (``keep_last``,
``reliable``, ``transient_local``, ``volatile``, ``automatic``), durations as ``sec``/``nsec``,
"not set" as the middleware reports it (``RMW_DURATION_INFINITE``, 9223372036 s 854775807 ns).
The history and depth are the publisher's (the middleware itself reports ``unknown`` and 0).

>>> print(qos_yaml([offered_qos(graph.QOS['latched'])]).splitlines()[:4])
['- history: keep_last', '  depth: 1', '  reliability: reliable', '  durability: transient_local']
>>> topic_qos(graph.Topic('/rosout', 'rcl_interfaces/msg/Log'))[0]['lifespan']
{'sec': 10, 'nsec': 0}

No rclpy here.
"""
import json
import re
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from scara_collab import graph

VERSION = 9                 # rosbag2_storage BagMetadata::version on Jazzy
ROS_DISTRO = 'jazzy'
STORAGE_IDENTIFIER = 'mcap'
METADATA_FILE = 'metadata.yaml'
METADATA_RECORD = 'rosbag2'  # the MCAP metadata record rosbag2's mcap plugin writes
SERIALIZATION_FORMAT = 'cdr'
#: RMW_DURATION_INFINITE, what the middleware reports for a duration policy that is not set
INFINITE = (9223372036, 854775807)
#: rcl's own publisher of /rosout (rcl_qos_profile_rosout_default): keep last 1000, reliable,
#: transient local, lifespan 10 s; the graph does not describe it
ROSOUT_QOS = graph.Qos(1000, latched=True)
ROSOUT_LIFESPAN = (10, 0)
_PLAIN = re.compile(r'^[A-Za-z_/][A-Za-z0-9_/.\-]*$')
_SPECIAL = frozenset(('y', 'n', 'yes', 'no', 'on', 'off', 'true', 'false', 'null', '~'))


def offered_qos(spec: graph.Qos, lifespan: Tuple[int, int] = INFINITE) -> Dict[str, object]:
    """Return a publisher's QoS profile as rosbag2 (version 9) serialises an offered profile.

    Keep last ``spec.depth``, reliable, transient local if ``spec.latched`` else volatile;
    deadline and liveliness lease not set (infinite), liveliness automatic.

    :param spec: the graph's named profile (:data:`scara_collab.graph.QOS`).
    :param lifespan: ``(sec, nsec)``; infinite unless the publisher sets one.
    :return: the policies in rosbag2's order, durations as ``{'sec', 'nsec'}``.
    """
    def duration(value: Tuple[int, int]) -> Dict[str, int]:
        return {'sec': int(value[0]), 'nsec': int(value[1])}

    return {'history': 'keep_last', 'depth': int(spec.depth), 'reliability': 'reliable',
            'durability': 'transient_local' if spec.latched else 'volatile',
            'deadline': duration(INFINITE), 'lifespan': duration(lifespan),
            'liveliness': 'automatic', 'liveliness_lease_duration': duration(INFINITE),
            'avoid_ros_namespace_conventions': False}


def topic_qos(topic: graph.Topic) -> List[Dict[str, object]]:
    """Return the offered profiles of a recorded topic (one publisher profile).

    ``/rosout`` is rcl's (:data:`ROSOUT_QOS`), every other topic its graph profile's.

    :param topic: a topic of :func:`scara_collab.graph.topics`.
    """
    if topic.name == '/rosout':
        return [offered_qos(ROSOUT_QOS, ROSOUT_LIFESPAN)]
    return [offered_qos(graph.QOS[topic.qos])]


def _scalar(value: object) -> str:
    if value is None:
        return '~'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    text = str(value)
    if _PLAIN.match(text) and text.lower() not in _SPECIAL:
        return text
    return json.dumps(text)  # a JSON string is a YAML double-quoted scalar


def to_yaml(value: object, indent: int = 0) -> str:
    """Return ``value`` as block YAML in yaml-cpp's layout (what rosbag2 writes).

    Maps as ``key: value`` lines, nested maps two spaces in, sequences as ``- `` items two
    spaces in under their key (at the left margin at the top), an empty map or ``None`` as
    ``~``, an empty sequence as ``[]``, strings plain where YAML reads them back as strings,
    else double-quoted. No trailing newline (``YAML::Dump``).

    >>> print(to_yaml({'a': [{'b': 1, 'c': ''}], 'd': {}}))
    a:
      - b: 1
        c: ""
    d: ~

    :param value: dicts, lists, strings, ints, bools and ``None``.
    :param indent: spaces before every line.
    """
    pad = ' ' * indent
    if isinstance(value, Mapping):
        if not value:
            return pad + '~'
        lines = []
        for key, item in value.items():
            if isinstance(item, (Mapping, list, tuple)) and item:
                child = indent + 2
                lines.append(f'{pad}{key}:\n' + to_yaml(item, child))
            else:
                lines.append(f'{pad}{key}: ' + to_yaml(item).lstrip())
        return '\n'.join(lines)
    if isinstance(value, (list, tuple)):
        if not value:
            return pad + '[]'
        items = []
        for item in value:
            text = to_yaml(item, indent + 2)
            items.append(f'{pad}- ' + text[indent + 2:])
        return '\n'.join(items)
    return pad + _scalar(value)


def qos_yaml(profiles: Sequence[Mapping[str, object]]) -> str:
    """Return offered profiles as the YAML text of a channel's ``offered_qos_profiles``.

    :param profiles: e.g. ``[offered_qos(graph.QOS['latched'])]``.
    """
    return to_yaml(list(profiles))


class TopicRecord:
    """One recorded topic for the metadata: the topic, its type hash, how many messages."""

    def __init__(self, topic: graph.Topic, type_hash: str, message_count: int):
        """Keep the fields."""
        self.topic = topic
        self.type_hash = type_hash
        self.message_count = int(message_count)


def bag_metadata(topics: Sequence[TopicRecord], file_name: str, starting_time: int,
                 duration: int, custom_data: Optional[Mapping[str, str]] = None
                 ) -> Dict[str, object]:
    """Return the bag metadata of one MCAP file, keys in rosbag2 Jazzy's order.

    Compression fields empty: MCAP's own chunk compression is used, as
    ``ros2 bag record -s mcap`` does by default.

    :param topics: every recorded topic, in channel order (also those without messages).
    :param file_name: the ``.mcap`` file, relative to the bag folder.
    :param starting_time: the first message's log time, ns since the epoch (of the clock
        recorded: sim time for a sim-time run).
    :param duration: last minus first log time, ns.
    :param custom_data: string pairs (rosbag2's ``--custom-data``); none gives ``~``.
    """
    count = sum(t.message_count for t in topics)
    return {
        'version': VERSION,
        'storage_identifier': STORAGE_IDENTIFIER,
        'duration': {'nanoseconds': int(duration)},
        'starting_time': {'nanoseconds_since_epoch': int(starting_time)},
        'message_count': count,
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.topic.name, 'type': t.topic.type,
                                'serialization_format': SERIALIZATION_FORMAT,
                                'offered_qos_profiles': topic_qos(t.topic),
                                'type_description_hash': t.type_hash},
             'message_count': t.message_count} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name,
                   'starting_time': {'nanoseconds_since_epoch': int(starting_time)},
                   'duration': {'nanoseconds': int(duration)},
                   'message_count': count}],
        'custom_data': {str(k): str(v) for k, v in (custom_data or {}).items()},
        'ros_distro': ROS_DISTRO,
    }


def metadata_yaml(metadata: Mapping[str, object]) -> str:
    """Return the text of ``metadata.yaml``: ``metadata`` under ``rosbag2_bagfile_information``.

    :param metadata: what :func:`bag_metadata` returns.
    """
    return to_yaml({'rosbag2_bagfile_information': metadata}) + '\n'
