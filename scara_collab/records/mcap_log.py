"""The MCAP file of a run, in the layout ``ros2 bag`` and Foxglove open: schemas, writing, reading.

:class:`McapWriter` writes messages that came off the wire as CDR bytes (never deserialized
or re-encoded) into one MCAP file in the layout of rosbag2's MCAP storage plugin; the node
side that takes them raw from the graph is :class:`scara_collab.nodes.mcap_recorder.McapRecorder`
(the launcher's ``--record``). No rclpy here.

- the ``ros2`` profile; per topic a channel with message encoding ``cdr`` and a schema named
  by the full type (``sensor_msgs/msg/JointState``) with encoding ``ros2msg``;
- the schema text is the type's ``.msg`` file followed by every nested type's, each after a
  line of 80 ``=`` and ``MSG: pkg/Type`` (:func:`ros2msg_definition`, the concatenation
  rosbag2 writes), read at run time from the message packages' ``share/<pkg>/msg`` folders;
- ``log_time`` is the receive time in sim time (as ``ros2 bag record --use-sim-time``): with
  ``sim_clock`` (the recording node is on sim time and ``/clock`` is recorded), a ``/clock``
  message is logged at its own time and every other message at the last tick received before
  it (receive order from the middleware's receive timestamps), so the file is consistent in
  itself; otherwise the wall receive time. Log times never go backwards. ``publish_time`` is
  the same (there is no sim-time send stamp); ``sequence`` counts the messages of each
  channel.

The run folder is a rosbag2 bag (Jazzy, storage ``mcap``; :mod:`scara_collab.records.bag`):
each channel carries the metadata ``offered_qos_profiles`` (the publisher's profile, so
``ros2 bag play`` republishes ``/emergency_stop`` latched) and ``topic_type_hash``;
:meth:`McapWriter.close` writes the MCAP metadata record ``rosbag2`` and ``metadata.yaml``
next to the file.

The file is chunked (``chunk_size`` bytes of messages, zstd-compressed) and the stream is
flushed at least every ``flush_period`` wall seconds, so a run that is killed without
:meth:`McapWriter.close` loses at most the last chunk; such a file has no footer but
:func:`iter_messages` (and ``mcap recover``) still read it. :meth:`McapWriter.close` writes the
summary and the footer.

Reading (a sketch, not a doctest: it needs a recorded run)::

    for topic, type_name, log_time, data in iter_messages('runs/x/run.mcap'): ...
"""
from functools import lru_cache
import importlib.util
import json
import os
from pathlib import Path
import re
import struct
import sys
import time
from typing import Dict, Iterable, Iterator, List, NamedTuple, Optional, Tuple, Union

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer

from scara_collab.graph import Topic
from scara_collab.records import bag, transforms

MCAP_FILE = 'run.mcap'
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
PROFILE = 'ros2'
SCHEMA_ENCODING = 'ros2msg'
MESSAGE_ENCODING = 'cdr'
SEPARATOR = '=' * 80
PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring'))
_TYPE = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$')
_FIELD = re.compile(r'^([A-Za-z][A-Za-z0-9_/]*)')


# --- message definitions ---------------------------------------------------------------------
def _split_type(type_name: str) -> Tuple[str, str]:
    """``'sensor_msgs/msg/JointState'`` or ``'sensor_msgs/JointState'`` -> package, name."""
    m = _TYPE.match(type_name)
    if m is None:
        raise ValueError(f'not a ROS 2 message type name: {type_name!r} (want pkg/msg/Type)')
    return m.group(1), m.group(2)


def _share_candidates(package: str) -> Iterator[Path]:
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            yield Path(prefix) / 'share' / package
    try:  # the prefix the Python package was installed into (a venv, a colcon install)
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        for parent in Path(spec.origin).resolve().parents:
            yield parent / 'share' / package
    yield Path(sys.prefix) / 'share' / package


@lru_cache(maxsize=None)
def msg_file(type_name: str) -> Path:
    """Return the ``.msg`` file of a message type.

    Looked for in ``<prefix>/share/<pkg>/msg/<Type>.msg`` for every prefix of
    ``AMENT_PREFIX_PATH``, the prefixes above the installed Python package ``<pkg>`` and
    ``sys.prefix``.

    :param type_name: ``pkg/msg/Type`` or ``pkg/Type``.
    :raises FileNotFoundError: if no prefix has it.
    """
    package, name = _split_type(type_name)
    tried = []
    for share in _share_candidates(package):
        path = share / 'msg' / f'{name}.msg'
        if path.is_file():
            return path
        tried.append(str(path))
    raise FileNotFoundError(f'no .msg file for {type_name}; looked in: ' + ', '.join(tried))


def msg_dependencies(text: str, package: str) -> List[str]:
    """Return the non-primitive field types of a ``.msg`` text, sorted, as written.

    A type without a package (``Point`` in ``geometry_msgs``) gets ``package``; constants
    and comments are skipped (constants have primitive types).

    :param text: the ``.msg`` file.
    :param package: the package the file belongs to.
    :return: e.g. ``['std_msgs/Header']`` for ``sensor_msgs/msg/JointState``.
    """
    deps = set()
    for line in text.splitlines():
        m = _FIELD.match(line.strip())
        if m is None or len(line.strip().split()) < 2:
            continue
        field_type = m.group(1)
        if field_type in PRIMITIVES:
            continue
        deps.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(deps)


@lru_cache(maxsize=None)
def ros2msg_definition(type_name: str) -> str:
    """Return the full ``ros2msg`` schema text of a type, as rosbag2's MCAP plugin writes it.

    The type's ``.msg`` text, then for every nested type not yet written (depth first, the
    dependencies of each file in sorted order) a newline, 80 ``=``, ``MSG: pkg/Type`` and
    that type's ``.msg`` text.

    :param type_name: ``pkg/msg/Type``.
    :raises FileNotFoundError: if a ``.msg`` file is missing.
    """
    seen = set()

    def expand(name: str, depth: int) -> str:
        if depth > 50:
            raise ValueError(f'message definition of {type_name} nests deeper than 50 levels')
        text = msg_file(name).read_text(encoding='utf-8')
        out = text
        for dep in msg_dependencies(text, _split_type(name)[0]):
            if dep not in seen:
                seen.add(dep)
                out += f'\n{SEPARATOR}\nMSG: {dep}\n' + expand(dep, depth + 1)
        return out

    return expand(type_name, 0)


@lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """Return the REP-2011 type hash of a message type (``RIHS01_...``), '' if not known.

    Read from the ``<Type>.json`` type description that rosidl installs beside the ``.msg``
    file (what rclpy reports as an endpoint's ``topic_type_hash``).

    :param type_name: ``pkg/msg/Type``.
    """
    try:
        description = msg_file(type_name).with_suffix('.json')
        hashes = json.loads(description.read_text(encoding='utf-8'))['type_hashes']
    except (OSError, ValueError, KeyError, TypeError):
        return ''
    full = '{}/msg/{}'.format(*_split_type(type_name))
    return next((h['hash_string'] for h in hashes if h.get('type_name') == full), '')


def _definition(type_name: str) -> str:
    """Return :func:`ros2msg_definition`; TFMessage's is written here if not installed."""
    if type_name != transforms.TF_TYPE:
        return ros2msg_definition(type_name)
    try:
        return ros2msg_definition(type_name)
    except FileNotFoundError:  # no PyPI wheel: the Jazzy definition and its dependencies
        nested = 'geometry_msgs/msg/TransformStamped'
        return (f'{transforms.TF_DEFINITION}\n{SEPARATOR}\nMSG: geometry_msgs/TransformStamped\n'
                f'{ros2msg_definition(nested)}')


def _hash(type_name: str) -> str:
    """Return :func:`type_hash`, with TFMessage's known Jazzy hash if it is not installed."""
    return type_hash(type_name) or (transforms.TF_HASH if type_name == transforms.TF_TYPE else '')


# --- writing ---------------------------------------------------------------------------------
def clock_nanoseconds(data: bytes) -> int:
    """Return the time in a serialized ``rosgraph_msgs/msg/Clock``, ns (0 if unreadable).

    CDR: a 4-byte encapsulation header (byte 1 is 1 for little endian), then ``int32 sec``
    and ``uint32 nanosec``.
    """
    if len(data) < 12:
        return 0
    sec, nsec = struct.unpack_from('<iI' if data[1] & 1 else '>iI', data, 4)
    return max(0, sec * 1_000_000_000 + nsec)


class McapWriter:
    """Write the messages of a run into an MCAP file (see the module docstring).

    :param path: the ``.mcap`` file (its folder is created; an existing file is replaced).
    :param topics: the channels, in order (:class:`scara_collab.graph.Topic`: name and type).
    :param sim_clock: log on the sim time of the recorded ``/clock`` (if it is among the
        topics), else on the wall receive time.
    :param chunk_size: bytes of messages per chunk (an unclean kill loses at most one).
    :param compression: ``'zstd'``, ``'lz4'`` or ``'none'``.
    :param flush_period: wall seconds between flushes of the file stream.
    :param urdf: the cell's URDF: the file also gets ``/robot_description``, ``/tf_static``
        and ``/tf`` made from it and the recorded ``/joint_states``
        (:class:`scara_collab.records.transforms.Transforms`), not taken off the wire; they are
        the last of :attr:`topics`, after the :attr:`wire_topics`.
    :raises FileNotFoundError: if a message definition is missing (no file is opened).
    """

    def __init__(self, path: Union[str, Path], topics: Iterable[Topic], sim_clock: bool = False,
                 chunk_size: int = 256 * 1024, compression: str = 'zstd',
                 flush_period: float = 2.0, urdf: Optional[str] = None):
        """Open the file and register a schema per type and a channel per topic."""
        self.path = Path(path)
        derived = {t.name for t in transforms.TOPICS} if urdf else set()
        self.wire_topics = [t for t in topics if t.name not in derived]
        self.topics = self.wire_topics + (list(transforms.TOPICS) if urdf else [])
        definitions = {t: _definition(t) for t in {t.type for t in self.topics}
                       | ({transforms.STATE_TYPE} if urdf else set())}  # fail early
        self._derive = transforms.Transforms(urdf, definitions) if urdf else None
        self._first_written = False
        compressions = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                        'none': CompressionType.NONE}
        if compression not in compressions:
            raise ValueError(f'compression must be one of {sorted(compressions)}')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, 'wb')
        self._writer = Writer(self._stream, chunk_size=int(chunk_size),
                              compression=compressions[compression])
        self._writer.start(profile=PROFILE, library='scara_collab mcap_log')
        schemas = {name: self._writer.register_schema(name, SCHEMA_ENCODING, text.encode())
                   for name, text in definitions.items()}
        self.counts: Dict[str, int] = {t.name: 0 for t in self.topics}
        self.closed = False
        self.last_log_time = 0
        self.first_log_time: Optional[int] = None
        self._flush_period = float(flush_period)
        self._next_flush = time.monotonic() + self._flush_period
        self.sim_clock = bool(sim_clock) and any(t.name == '/clock' and t.type == CLOCK_TYPE
                                                 for t in self.topics)
        # per topic index: (channel id, topic name, is it /clock)
        self._channels: List[Tuple[int, str, bool]] = [
            (self._writer.register_channel(t.name, MESSAGE_ENCODING, schemas[t.type], {
                'offered_qos_profiles': bag.qos_yaml(bag.topic_qos(t)),
                'topic_type_hash': _hash(t.type)}), t.name, t.type == CLOCK_TYPE)
            for t in self.topics]
        self._index = {name: k for k, (_, name, _) in enumerate(self._channels)}

    @property
    def messages(self) -> int:
        """Messages written so far."""
        return sum(self.counts.values())

    def write(self, batch: List[Tuple[int, int, bytes]], now: int = 0) -> int:
        """Write a batch of received messages in receive order; return how many.

        :param batch: ``(receive time ns or 0, topic index in topics, CDR bytes)`` each.
        :param now: wall time, ns, for messages without a receive time (off sim time).
        """
        if self.closed or not batch:
            return 0
        batch.sort(key=_receive_order)
        add = self._writer.add_message
        counts, channels = self.counts, self._channels
        last = self.last_log_time
        for received, k, data in batch:
            channel, topic, is_clock = channels[k]
            if self.sim_clock:
                t = max(clock_nanoseconds(data), last) if is_clock else last
            else:
                t = max(received or now, last)
            last = t
            if self._derive is not None and not self._first_written:
                self._first_written = True  # the description and the static tree, once
                for name, derived in self._derive.first():
                    self._add(name, t, derived)
            seq = counts[topic] = counts[topic] + 1
            add(channel_id=channel, log_time=t, publish_time=t, data=data, sequence=seq)
            if self.first_log_time is None:
                self.first_log_time = t
            if self._derive is not None and topic == '/joint_states':
                tf = self._derive.from_state(data)
                if tf:
                    self._add('/tf', t, tf)
        self.last_log_time = last
        if time.monotonic() >= self._next_flush:
            self.flush()
        return len(batch)

    def _add(self, topic: str, t: int, data: bytes) -> None:
        """Write one derived message on ``topic`` at log time ``t``."""
        seq = self.counts[topic] = self.counts[topic] + 1
        self._writer.add_message(channel_id=self._channels[self._index[topic]][0], log_time=t,
                                 publish_time=t, data=data, sequence=seq)

    def flush(self) -> None:
        """Push what the writer has handed to the file stream to the OS (not the open chunk)."""
        self._next_flush = time.monotonic() + self._flush_period
        if not self.closed:
            self._stream.flush()

    def bag_metadata(self) -> Dict[str, object]:
        """Return the rosbag2 metadata of what is written so far (:func:`bag.bag_metadata`)."""
        first = self.first_log_time or 0
        return bag.bag_metadata(
            [bag.TopicRecord(t, _hash(t.type), self.counts[t.name]) for t in self.topics],
            self.path.name, first, self.last_log_time - first if self.messages else 0)

    def close(self) -> Dict[str, object]:
        """Write the rosbag2 metadata, the summary and the footer, close the file (idempotent).

        Then ``metadata.yaml`` beside the file makes its folder a rosbag2 bag.

        :return: ``{'mcap': {'file', 'messages', 'topics', 'bytes'}}`` for the run summary.
        """
        if not self.closed:
            self.closed = True
            metadata = self.bag_metadata()
            try:
                self._writer.add_metadata(bag.METADATA_RECORD, {
                    'serialized_metadata': bag.to_yaml(metadata), 'ROS_DISTRO': bag.ROS_DISTRO})
                self._writer.finish()
            finally:
                self._stream.close()
            (self.path.parent / bag.METADATA_FILE).write_text(bag.metadata_yaml(metadata),
                                                              encoding='utf-8')
        return {'mcap': {'file': self.path.name, 'messages': self.messages,
                         'topics': {k: v for k, v in self.counts.items() if v},
                         'bytes': self.path.stat().st_size if self.path.exists() else 0}}


def _receive_order(entry: tuple) -> int:
    return entry[0]


# --- reading ---------------------------------------------------------------------------------
class RawMessage(NamedTuple):
    """One recorded message: topic, full type name, log time (ns), CDR bytes."""

    topic: str
    type: str
    log_time: int
    data: bytes


class Reading:
    """What :func:`iter_messages` found: ``complete`` is False for a file without a footer."""

    def __init__(self):
        """Start as complete, with no error."""
        self.complete = True
        self.error = ''


def iter_messages(path: Union[str, Path], topics: Optional[Iterable[str]] = None,
                  reading: Optional[Reading] = None) -> Iterator[RawMessage]:
    """Yield the messages of an MCAP file in file order (= log time order for our files).

    Reads linearly, so it also reads a file that was cut short (a killed run): the messages
    of every complete chunk are yielded and ``reading.complete`` is set to False.

    :param path: the ``.mcap`` file.
    :param topics: only these topics (default all).
    :param reading: filled in with ``complete`` and ``error`` when the iteration ends.
    """
    reading = reading if reading is not None else Reading()
    wanted = None if topics is None else set(topics)
    with open(path, 'rb') as f:
        reader = NonSeekingReader(f)
        try:
            for schema, channel, msg in reader.iter_messages(topics=wanted,
                                                             log_time_order=False):
                yield RawMessage(channel.topic, schema.name if schema else '', msg.log_time,
                                 msg.data)
        except (McapError, EOFError, ValueError, struct.error) as exc:  # cut short: keep the rest
            reading.complete = False
            reading.error = f'{type(exc).__name__}: {exc}'
