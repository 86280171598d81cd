"""The job protocol: every status the nodes exchange, typed, in one module.

Each status is a frozen dataclass with ``to_msg()`` and ``from_msg()`` on the standard
``diagnostic_msgs/DiagnosticStatus`` (``name``, ``level``, a readable ``message`` and the
fields as key-values). No other module formats or parses these key-values: a node builds the
dataclass and publishes ``to_msg()``; a subscriber calls ``from_msg()`` and reads typed fields
(a malformed message raises :class:`ProtocolError`, which the subscriber logs and drops).

================================  ==================  =======================================
topic                             type                publisher
================================  ==================  =======================================
``/<robot>/planner_status``       :class:`PlannerStatus`   planner
``/<robot>/execution_status``     :class:`ExecutionStatus` bridge
``/conveyor/events``              :class:`ItemEvent`       bridge
``/automation_manager/stats``     :class:`JobStats`        automation manager
``/replication_manager/status``   :class:`MirrorStatus`    replication manager
``/collision_monitor/status``     :class:`MonitorStatus`   collision monitor
``/collision_monitor/stops``      :class:`StopEvent`       collision monitor
``line/handoff``                  :class:`LineHandoff`     bridge (a cell of a line)
================================  ==================  =======================================

**Encoding.** Each status class states how each of its fields travels, in its table
``FIELDS`` (field name -> :class:`Codec`): one key-value per field, keyed by the field's name,
except a table (:data:`COUNTS`, :data:`NAMES`: one key-value per entry, ``counts.sorted``) and
records named by an id (:data:`HANDOFFS`, :data:`ON_BELT`: one key-value per value of each,
``handoffs.1000012.time``). The values: text as it is; integers in decimal;
floats as ``repr`` (they come back exactly; NaN is refused, ``inf`` is a float); ``true`` /
``false``; an absent optional value as the empty string. A field with a default may be left
out of a message; a field without one may not.

**Moves** are named by the request that asked for them, ``<robot>/<request ns>``
(:mod:`scara_collab.core.moves`): the planner puts the id in the ``header.frame_id`` of the
``JointTrajectory`` it publishes, the bridge reports on that id, so a status always says which
move it is about, from the request to the end of the motion.

**A move's request.** A point (``/<robot>/target``, ``geometry_msgs/PointStamped``, frame
``world`` or ``<robot>_base``; ``/collab/target`` for a mirrored pair), or a plan of the move
(``/<robot>/target_trajectory``, ``trajectory_msgs/JointTrajectory``: positions, velocities
and accelerations of the arm's joints from ``time_from_start`` 0; the target is its last
point). The sorting job sends its own plan, so the planner schedules it without planning it
again (:mod:`scara_collab.nodes.planner`). Either way ``header.stamp`` is the request.
"""
from dataclasses import dataclass, field, fields, KW_ONLY, MISSING
import math
import numbers
from typing import Callable, ClassVar, Dict, List, Mapping, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from scara_collab.core import sorting
from scara_collab.core.line import Handoff, OnBelt
from scara_collab.core.move_time import lateness
from scara_collab.core.moves import EXECUTION_STATES, move_id, PLANNER_STATES
from scara_collab.core.separation_monitor import PersonSeen

LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
          'ERROR': DiagnosticStatus.ERROR, 'STALE': DiagnosticStatus.STALE}


class ProtocolError(ValueError):
    """A status message does not follow the protocol; the text says why."""


#: what :meth:`Codec.decode` returns for a field the message has no key-value of
ABSENT = object()


# --- how a field travels ---------------------------------------------------------------------
class Codec:
    """How one field of a status travels as key-values, and how it is read back.

    :param kind: what the value is, in words (for the errors).
    :param write: value -> text; raises ``ValueError`` or ``TypeError`` on a value of the
        wrong kind.
    :param read: text -> value; raises ``ValueError`` on a text that is not one.

    >>> INT.encode('request', 15)
    [('request', '15')]
    >>> INT.decode('request', {'request': '15'}), INT.decode('delay', {'request': '15'}) is ABSENT
    (15, True)
    """

    def __init__(self, kind: str, write: Callable[[object], str], read: Callable[[str], object]):
        """Keep the two conversions."""
        self.kind, self.write, self.read = kind, write, read

    def encode(self, key: str, value) -> List[Tuple[str, str]]:
        """Return the key-values of field ``key`` holding ``value``."""
        return [(key, self.write(value))]

    def decode(self, key: str, values: Mapping[str, str]):
        """Return field ``key`` read from a message's key-values, :data:`ABSENT` if it has none.

        :raises ProtocolError: a value that is not of the field's kind, naming the key.
        """
        if key not in values:
            return ABSENT
        return self.parse(key, values[key])

    def parse(self, key: str, text: str):
        """Return the value ``text`` stands for (the value of ``key``).

        :raises ProtocolError: it stands for none, naming the key.
        """
        try:
            return self.read(text)
        except (ValueError, TypeError) as exc:
            raise ProtocolError(f'{key}={text!r} is not {self.kind} ({exc})') from None


class OrNone(Codec):
    """A value of ``codec``'s kind or None (the empty string)."""

    def __init__(self, codec: Codec):
        """Wrap ``codec``."""
        super().__init__(f'{codec.kind} or empty', lambda v: '' if v is None else codec.write(v),
                         lambda t: None if t == '' else codec.read(t))


class Table(Codec):
    """A dict of ``codec``'s values: one key-value per entry, keyed ``<field>.<entry>``.

    >>> COUNTS.encode('counts', {'sorted': 3, 'missed': 0})
    [('counts.sorted', '3'), ('counts.missed', '0')]
    >>> COUNTS.decode('counts', {'counts.sorted': '3', 'time': '1.0'})
    {'sorted': 3}
    """

    def __init__(self, codec: Codec):
        """Wrap ``codec`` (the entries' kind)."""
        super().__init__(f'a table of {codec.kind}', codec.write, codec.read)

    def encode(self, key: str, value) -> List[Tuple[str, str]]:
        """Return one key-value per entry of ``value`` (none for an empty dict)."""
        return [(f'{key}.{entry}', self.write(v)) for entry, v in dict(value).items()]

    def decode(self, key: str, values: Mapping[str, str]):
        """Return the entries keyed ``<key>.<entry>``, in message order (:data:`ABSENT`: none)."""
        prefix = key + '.'
        out = {k[len(prefix):]: self.parse(k, text) for k, text in values.items()
               if k.startswith(prefix)}
        return out or ABSENT


class Records(Codec):
    """A tuple of records named by an integer id: one key-value per value, ``<field>.<id>.<name>``.

    :param record: the record class, built as ``record(id, **values)``.
    :param ident: the name of the record's id (an ``int``, its first field).
    :param codecs: each value's codec, by name, in the record's order after the id.

    >>> codec = Records(Handoff, 'item', cls=TEXT, y=FLOAT, time=FLOAT)
    >>> pairs = codec.encode('handoffs', (Handoff(7, 'red', 0.1, 2.5),))
    >>> pairs
    [('handoffs.7.cls', 'red'), ('handoffs.7.y', '0.1'), ('handoffs.7.time', '2.5')]
    >>> codec.decode('handoffs', dict(pairs))
    (Handoff(item=7, cls='red', y=0.1, time=2.5),)
    """

    def __init__(self, record: type, ident: str, **codecs: Codec):
        """Keep the record class, the name of its id and its values' codecs."""
        super().__init__(f'{record.__name__} records', str, str)
        self.record, self.ident, self.codecs = record, ident, codecs

    def encode(self, key: str, value) -> List[Tuple[str, str]]:
        """Return the key-values of every record of ``value`` (none for an empty tuple)."""
        return [(f'{key}.{_write_int(getattr(r, self.ident))}.{name}',
                 codec.write(getattr(r, name)))
                for r in value for name, codec in self.codecs.items()]

    def decode(self, key: str, values: Mapping[str, str]):
        """Return the records keyed ``<key>.<id>.<name>``, in message order (:data:`ABSENT`: none).

        :raises ProtocolError: an id that is not an integer, a value of the wrong kind, a
            record without one of its values.
        """
        prefix = key + '.'
        found: Dict[int, Dict[str, object]] = {}
        for k, text in values.items():
            if not k.startswith(prefix):
                continue
            ident, _, name = k[len(prefix):].partition('.')
            if name in self.codecs:
                found.setdefault(INT.parse(k, ident), {})[name] = self.codecs[name].parse(k, text)
        for ident, got in found.items():
            if len(got) < len(self.codecs):
                missing = [n for n in self.codecs if n not in got]
                raise ProtocolError(f'{key}.{ident}: no {missing}')
        return tuple(self.record(ident, **got) for ident, got in found.items()) or ABSENT


def _write_int(v) -> str:
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise TypeError(f'{v!r} is not an integer')
    return str(int(v))


def _write_float(v) -> str:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f'{v!r} is not a number')
    return repr(float(v))  # round-trips exactly (numpy floats too)


def _read_float(text: str) -> float:
    v = float(text)
    if math.isnan(v):
        raise ValueError('NaN')
    return v


def _read_bool(text: str) -> bool:
    if text not in ('true', 'false'):
        raise ValueError('neither true nor false')
    return text == 'true'


#: text as it is
TEXT = Codec('a text', str, str)
#: an integer, in decimal
INT = Codec('an integer', _write_int, int)
#: a float as ``repr`` (exact); NaN refused
FLOAT = Codec('a number', _write_float, _read_float)
#: ``true`` or ``false``
BOOL = Codec('true or false', lambda v: 'true' if v else 'false', _read_bool)
#: a float or None (the empty string)
OPTIONAL_FLOAT = OrNone(FLOAT)
#: a dict of integers (counts by name)
COUNTS = Table(INT)
#: a dict of texts (a name by name)
NAMES = Table(TEXT)
#: a line's handoffs (:class:`~scara_collab.core.line.Handoff`): ``handoffs.<item>.cls``,
#: ``.y``, ``.time``
HANDOFFS = Records(Handoff, 'item', cls=TEXT, y=FLOAT, time=FLOAT)
#: the items on a section's belt (:class:`~scara_collab.core.line.OnBelt`):
#: ``belt.<item>.cls``, ``.x``, ``.y``
ON_BELT = Records(OnBelt, 'item', cls=TEXT, x=FLOAT, y=FLOAT)


class _Status:
    """Fields <-> ``DiagnosticStatus`` key-values, each field as its class's ``FIELDS`` says."""

    #: the ``DiagnosticStatus.name`` suffix or fixed name of this status
    KIND: ClassVar[str] = ''
    #: ``(field, allowed values)`` checked on construction, or None
    CHOICES: ClassVar[Optional[Tuple[str, tuple]]] = None
    #: how each field travels (every field of the dataclass, by name)
    FIELDS: ClassVar[Dict[str, Codec]] = {}

    def __post_init__(self):
        if self.CHOICES is not None:
            key, allowed = self.CHOICES
            if getattr(self, key) not in allowed:
                raise ValueError(f'{key} {getattr(self, key)!r} is not one of {allowed}')

    def level(self) -> str:
        """``'OK'``, ``'WARN'`` or ``'ERROR'`` for the message's ``level``."""
        return 'OK'

    def text(self) -> str:
        """Return the readable one-line ``message``."""
        return ''

    def name(self) -> str:
        """Return the ``DiagnosticStatus.name``."""
        return self.KIND

    def to_msg(self) -> DiagnosticStatus:
        """Return the status as a ``DiagnosticStatus``.

        :raises TypeError: a field holding a value of the wrong kind (a float count).
        """
        msg = DiagnosticStatus(level=LEVELS[self.level()], name=self.name(),
                               message=self.text())
        msg.values = [KeyValue(key=k, value=v) for f in fields(self)
                      for k, v in self.FIELDS[f.name].encode(f.name, getattr(self, f.name))]
        return msg

    @classmethod
    def from_msg(cls, msg: DiagnosticStatus):
        """Parse a ``DiagnosticStatus`` built by :meth:`to_msg`.

        :raises ProtocolError: a missing or malformed field.
        """
        values = {kv.key: kv.value for kv in msg.values}
        kwargs = {}
        for f in fields(cls):
            value = cls.FIELDS[f.name].decode(f.name, values)
            if value is not ABSENT:
                kwargs[f.name] = value
            elif f.default is MISSING and f.default_factory is MISSING:
                raise ProtocolError(f'{cls.__name__}: no {f.name!r} in {sorted(values)}')
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise ProtocolError(f'{cls.__name__}: {exc}') from None


_MOVE_FIELDS = {'robot': TEXT, 'state': TEXT, 'move': TEXT, 'reason': TEXT,
                'start': OPTIONAL_FLOAT, 'end': OPTIONAL_FLOAT}


@dataclass(frozen=True)
class _MoveStatus(_Status):
    """What every status about one arm's move says: whose, what state, which move, why, when.

    ``reason``, ``start`` and ``end`` (sim s) are keyword-only: each status adds its own
    fields after the move's name.
    """

    robot: str
    state: str
    move: str
    _: KW_ONLY
    reason: str = ''
    start: Optional[float] = None
    end: Optional[float] = None


# --- planner ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlannerStatus(_MoveStatus):
    """What a planner did with one request (``/<robot>/planner_status``).

    ``planned``: the move is committed and published, starting at ``start`` (``delay``
    seconds after it was asked, because of the other arm) and ending at ``end``; ``queued``:
    held until the arm's running move ends; ``waiting``: the other arm blocks it, retried
    when that arm moves; ``refused``: not executed, ``reason`` says why; ``superseded``: a
    newer request replaced it before it was planned.
    """

    request: int
    delay: float = 0.0
    kind: str = ''            # 'line' or 'joint' for planned moves

    KIND: ClassVar[str] = 'planner'
    CHOICES: ClassVar[Tuple[str, tuple]] = ('state', PLANNER_STATES)
    FIELDS: ClassVar[Dict[str, Codec]] = dict(_MOVE_FIELDS, request=INT, delay=FLOAT, kind=TEXT)

    @classmethod
    def of(cls, robot: str, status) -> 'PlannerStatus':
        """Return what ``robot``'s planner reports for its core's ``status``.

        :param status: a :class:`scara_collab.core.arm_planner.Status`.
        """
        return cls(robot, status.state, move_id(robot, status.request), status.request,
                   reason=status.reason, start=status.start, end=status.end,
                   delay=status.delay, kind=status.kind)

    def name(self) -> str:
        """Return ``'<robot>/planner'``."""
        return f'{self.robot}/planner'

    def level(self) -> str:
        """Return ``'ERROR'`` if refused, ``'WARN'`` if waiting, superseded or delayed."""
        if self.state == 'refused':
            return 'ERROR'
        if self.state in ('waiting', 'superseded') or self.delay > 0:
            return 'WARN'
        return 'OK'

    def text(self) -> str:
        """Return the move, its kind and time window (planned) or its state and reason."""
        if self.state == 'planned':
            late = (f'; delayed by {self.delay:.2f} s for the other arm' if self.delay > 0
                    else '')
            return (f'move {self.move}: {self.kind or "move"} from t={self.start:.3f} s to '
                    f't={self.end:.3f} s{late}{"; " + self.reason if self.reason else ""}')
        return f'move {self.move} {self.state}' + (f': {self.reason}' if self.reason else '')


# --- bridge ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ExecutionStatus(_MoveStatus):
    """What the bridge does with one trajectory (``/<robot>/execution_status``).

    ``accepted``: it runs from ``start`` to ``end`` (sim s; ``stamp`` is the start it asked
    for, ``start`` later means it came late); ``refused``: not executed (``reason``), the arm
    keeps its command; ``finished``: it ran to its end; ``preempted``: a newer trajectory
    (the move ``by``) replaced it; ``held``: a protective or emergency stop, or a silent
    lockstep guard (the collision monitor, :mod:`scara_collab.nodes.lockstep`), holds the arm
    (the move is aborted; ``end``: the sim s the arm's brake brings it to rest); ``cleared``:
    the stop was released, or the guard answers again.
    """

    time: float
    stamp: Optional[float] = None
    by: str = ''

    KIND: ClassVar[str] = 'execution'
    CHOICES: ClassVar[Tuple[str, tuple]] = ('state', EXECUTION_STATES)
    FIELDS: ClassVar[Dict[str, Codec]] = dict(_MOVE_FIELDS, time=FLOAT, stamp=OPTIONAL_FLOAT,
                                              by=TEXT)

    def name(self) -> str:
        """Return ``'<robot>/execution'``."""
        return f'{self.robot}/execution'

    def level(self) -> str:
        """Return ``'ERROR'`` if refused, ``'WARN'`` if held, else ``'OK'``."""
        return {'refused': 'ERROR', 'held': 'WARN'}.get(self.state, 'OK')

    def text(self) -> str:
        """Return the move, its state and time, its run window if accepted, and the reason."""
        what = f'move {self.move or "(no id)"} {self.state} at t={self.time:.3f} s'
        if self.state == 'accepted':
            what += f': runs t={self.start:.3f}..{self.end:.3f} s'
        return what + (f': {self.reason}' if self.reason else '')

    @property
    def late(self) -> float:
        """Seconds the bridge started after the requested stamp (0 if on time or unstamped).

        The start rule's measure (:func:`scara_collab.core.move_time.lateness`).
        """
        if self.state != 'accepted' or self.start is None:
            return 0.0
        return lateness(self.stamp, self.start)


# --- items -----------------------------------------------------------------------------------
ITEM_EVENTS, COUNTED = sorting.ITEM_EVENTS, sorting.COUNTED


@dataclass(frozen=True)
class ItemEvent(_Status):
    """Something that happened to an item (``/conveyor/events``): the one source of counts.

    ``robot``: the arm involved (gripper, bin, last holder); ``cause``: for ``dropped`` and
    ``missed``, what made the item leave the belt (e.g. ``knocked by scara_left link 2``).
    """

    kind: str
    item: int
    cls: str
    time: float
    robot: str = ''
    cause: str = ''

    CHOICES: ClassVar[Tuple[str, tuple]] = ('kind', ITEM_EVENTS)
    FIELDS: ClassVar[Dict[str, Codec]] = {'kind': TEXT, 'item': INT, 'cls': TEXT, 'time': FLOAT,
                                          'robot': TEXT, 'cause': TEXT}

    def name(self) -> str:
        """Return the event's kind (``'sorted'``, ``'missed'``, ...)."""
        return self.kind

    def level(self) -> str:
        """Return ``'WARN'`` for a missed, dropped or wrong-bin item, else ``'OK'``."""
        return 'WARN' if self.kind in ('missed', 'dropped', 'wrong_bin') else 'OK'

    def text(self) -> str:
        """Return the item, its class, the event, the robot and the cause."""
        by = f' by {self.robot}' if self.robot else ''
        return f'item {self.item} ({self.cls}) {self.kind}{by}' + (
            f': {self.cause}' if self.cause else '')


# --- job, mirror, monitor --------------------------------------------------------------------
@dataclass(frozen=True)
class JobStats(_Status):
    """The sorting job's own figures (``/automation_manager/stats``, 1 Hz sim time).

    Item counts are the bridge's events as the manager heard them (the run summary counts
    ``/conveyor/events`` itself); ``give_ups`` and ``retries`` are the job's decisions.
    """

    mode: str
    running: bool
    time: float
    start_time: Optional[float]
    counts: Dict[str, int] = field(default_factory=dict)
    sorted_by: Dict[str, int] = field(default_factory=dict)
    items_per_minute: float = 0.0
    give_ups: int = 0
    retries: int = 0
    phases: Dict[str, str] = field(default_factory=dict)
    last_give_up: str = ''
    #: missed items the job last left for a person in the cell (its note said so)
    missed_due_to_person: int = 0

    KIND: ClassVar[str] = 'automation_manager'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'mode': TEXT, 'running': BOOL, 'time': FLOAT, 'start_time': OPTIONAL_FLOAT,
        'counts': COUNTS, 'sorted_by': COUNTS, 'items_per_minute': FLOAT, 'give_ups': INT,
        'retries': INT, 'phases': NAMES, 'last_give_up': TEXT, 'missed_due_to_person': INT}

    def text(self) -> str:
        """Return the sorted, missed and dropped counts, the rate and the give-ups."""
        c = self.counts
        return (f'{c.get("sorted", 0)} sorted, {c.get("missed", 0)} missed, '
                f'{c.get("dropped", 0)} dropped, {self.items_per_minute:.1f}/min, '
                f'{self.give_ups} give-ups')


@dataclass(frozen=True)
class MirrorStatus(_Status):
    """The replication manager's mirror figures (``/replication_manager/status``).

    ``error_max`` is the largest mirror error (m) measured while both arms ran moves of the
    same request that the bridge started at the same instant (``in_step_moves`` of them);
    ``not_in_step`` counts replicated requests whose two moves did not start together
    (``last_reason`` says why).
    """

    enabled: bool
    time: float
    error: Optional[float] = None
    error_max: Optional[float] = None
    error_max_time: Optional[float] = None
    in_step_moves: int = 0
    not_in_step: int = 0
    last_reason: str = ''

    KIND: ClassVar[str] = 'replication_manager'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'enabled': BOOL, 'time': FLOAT, 'error': OPTIONAL_FLOAT, 'error_max': OPTIONAL_FLOAT,
        'error_max_time': OPTIONAL_FLOAT, 'in_step_moves': INT, 'not_in_step': INT,
        'last_reason': TEXT}

    def text(self) -> str:
        """Return whether mirroring is on, the in-step error maximum and the step counts."""
        mx = 'n/a' if self.error_max is None else f'{self.error_max * 1e3:.3f} mm'
        return (f'mirroring {"on" if self.enabled else "off"}: in-step error max {mx} over '
                f'{self.in_step_moves} moves, {self.not_in_step} not in step')


@dataclass(frozen=True)
class MonitorStatus(_Status):
    """The collision monitor's figures (``/collision_monitor/status``): the separation source.

    ``distance``: the latest arm-to-arm capsule surface distance (m); ``minimum`` and
    ``minimum_time``: the smallest so far and when; ``stopped``: the emergency stop is
    latched, ``reason`` says why.
    """

    time: float
    distance: Optional[float]
    minimum: Optional[float]
    minimum_time: Optional[float]
    margin: float
    stopped: bool
    reason: str = ''
    kind: str = ''          # the standing stop's kind (:data:`STOP_KINDS`), '' if none
    protective: int = 0     # protective stops so far
    emergency: int = 0      # emergency stops so far

    KIND: ClassVar[str] = 'collision_monitor'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'time': FLOAT, 'distance': OPTIONAL_FLOAT, 'minimum': OPTIONAL_FLOAT,
        'minimum_time': OPTIONAL_FLOAT, 'margin': FLOAT, 'stopped': BOOL, 'reason': TEXT,
        'kind': TEXT, 'protective': INT, 'emergency': INT}

    def level(self) -> str:
        """Return ``'ERROR'`` under an emergency stop, ``'WARN'`` under a protective one."""
        if not self.stopped:
            return 'OK'
        return 'WARN' if self.kind == 'protective' else 'ERROR'

    def text(self) -> str:
        """Return the stop's kind and reason, or the arms' distance and the margin."""
        if self.stopped:
            return f'{self.kind or "emergency"} stop: {self.reason}'
        d = 'n/a' if self.distance is None else f'{self.distance:.3f} m'
        return f'arms {d} apart (margin {self.margin} m)'


#: ISO 10218's two stops: ``protective`` (a predicted conflict, an unusable or stale joint
#: state, a silent guard: released by itself once the cause is gone) and ``emergency`` (an
#: outside request, a broken margin: held until ``/collision_monitor/clear``)
STOP_KINDS = ('protective', 'emergency')


@dataclass(frozen=True)
class StopEvent(_Status):
    """A stop of both arms begins or ends (``/collision_monitor/stops``).

    ``state`` ``begin`` at sim time ``time`` with its ``cause``; ``end`` when it is released
    (``since``: when it began, so ``time - since`` is the sim time it cost). ``kind`` is one
    of :data:`STOP_KINDS`.
    """

    kind: str
    state: str
    time: float
    cause: str
    since: Optional[float] = None

    KIND: ClassVar[str] = 'collision_monitor/stop'
    CHOICES: ClassVar[Tuple[str, tuple]] = ('kind', STOP_KINDS)
    FIELDS: ClassVar[Dict[str, Codec]] = {'kind': TEXT, 'state': TEXT, 'time': FLOAT,
                                          'cause': TEXT, 'since': OPTIONAL_FLOAT}

    def level(self) -> str:
        """Return ``'ERROR'`` for an emergency stop's begin, ``'WARN'`` for a protective one."""
        if self.state == 'end':
            return 'OK'
        return 'ERROR' if self.kind == 'emergency' else 'WARN'

    def text(self) -> str:
        """Return the stop, its time and cause (and its cost when it ends)."""
        if self.state == 'end':
            lost = '' if self.since is None else f' after {self.time - self.since:.3f} s'
            return f'{self.kind} stop released at t={self.time:.3f} s{lost}: {self.cause}'
        return f'{self.kind} stop at t={self.time:.3f} s: {self.cause}'


@dataclass(frozen=True)
class SimStatus(_Status):
    """The simulator's state (the bridge, on ``/diagnostics`` once a second of sim time).

    ``time``: sim s; ``paused``: ``/sim/pause`` holds the clock; ``estop``: the emergency
    stop holds both arms; ``moving``: arms executing a trajectory; ``items``: on the belt or
    held; ``absent``: lockstep guards missing (the arms are held until they answer).
    """

    time: float
    paused: bool
    estop: bool
    moving: int
    items: int
    absent: str = ''

    KIND: ClassVar[str] = 'pybullet_bridge'
    FIELDS: ClassVar[Dict[str, Codec]] = {'time': FLOAT, 'paused': BOOL, 'estop': BOOL,
                                          'moving': INT, 'items': INT, 'absent': TEXT}

    def level(self) -> str:
        """Return ``'ERROR'`` under the e-stop or a missing guard, ``'WARN'`` paused, else OK."""
        if self.estop or self.absent:
            return 'ERROR'
        return 'WARN' if self.paused else 'OK'

    def text(self) -> str:
        """Return what holds the simulation, or that it runs."""
        if self.estop:
            return f'emergency stop: both arms held at sim t={self.time:.3f} s'
        if self.absent:
            return f'arms held: {self.absent} silent'
        state = 'paused' if self.paused else 'running'
        return f'{state} at sim t={self.time:.3f} s, {self.moving} arm(s) moving'


# --- a line of cells -------------------------------------------------------------------------
@dataclass(frozen=True)
class LineHandoff(_Status):
    """What a cell of a line hands on, and how far it has run (``line/handoff``).

    ``cell``: the sender's index along the line; ``frontier``: the sim time up to which every
    item it hands on is in this message or an earlier one; ``handed``: items handed on up to
    the frontier, all told; ``handoffs``: the handoffs of the last seconds before the frontier
    (repeated from message to message, so a lost message is made up for); ``belt``: the items
    resting on the sender's belt at the frontier (what its section still carries should it
    die; :mod:`scara_collab.core.line`). The records travel as :data:`HANDOFFS` and
    :data:`ON_BELT` say: one key-value per value, ``handoffs.<item>.time`` and the like.
    """

    cell: int
    frontier: float
    handed: int
    handoffs: Tuple[Handoff, ...] = ()
    belt: Tuple[OnBelt, ...] = ()

    KIND: ClassVar[str] = 'line_handoff'
    FIELDS: ClassVar[Dict[str, Codec]] = {'cell': INT, 'frontier': FLOAT, 'handed': INT,
                                          'handoffs': HANDOFFS, 'belt': ON_BELT}

    def __post_init__(self):  # noqa: D105 (the checks the message's fields must pass)
        if not math.isfinite(self.frontier):
            raise ValueError(f'frontier must be a finite sim time, got {self.frontier!r}')
        if self.cell < 0 or self.handed < 0:
            raise ValueError(f'cell {self.cell!r} or handed {self.handed!r} < 0')
        for h in self.handoffs:
            _check_item('handoff', h.item, h.cls, y=h.y, time=h.time)
        for b in self.belt:
            _check_item('item on the belt', b.item, b.cls, x=b.x, y=b.y)

    def text(self) -> str:
        """Return the frontier and the count."""
        return (f'cell {self.cell} at sim t={self.frontier:.3f} s, {self.handed} handed on, '
                f'{len(self.handoffs)} in this message')


def _check_item(what: str, item: int, cls: str, **numbers: float) -> None:
    """Refuse an item of a line message with a negative id, no class or a non-finite number."""
    if item < 0:
        raise ValueError(f'a {what} id must be >= 0, got {item!r}')
    if not cls:
        raise ValueError(f'{what} {item}: cls must name a class, got {cls!r}')
    for key, v in numbers.items():
        if not math.isfinite(v):
            raise ValueError(f'{what} {item}: {key} must be a finite number, got {v!r}')


# --- a person in the cell ----------------------------------------------------------------------
#: a float per arm (or per joint), keyed by its name
FLOATS = Table(FLOAT)
#: a flag per arm, keyed by its name
FLAGS = Table(BOOL)


@dataclass(frozen=True)
class TrajectoryClock(_Status):
    """One arm's trajectory clock (``/<robot>/trajectory_clock``, the bridge).

    Published in a cell with a safety scanner, at a scan when the clock has changed since it
    was last said (with every scan while the arm runs slowed), and when the bridge brakes the
    arm off its path; never otherwise. ``lag``: sim time minus the arm's trajectory time, s
    (what speed scaling has cost it; the times of its moves, stamps included, are trajectory
    time); ``scale``: the factor its trajectory runs at now; ``target``: the factor asked
    (``/<robot>/speed_scaling``); ``planned``: its trajectory's velocity at the trajectory
    time, as planned (unscaled), by joint name; ``held_back``: its path-keeping stop fell
    behind braking, so the bridge brakes it.
    """

    robot: str
    time: float
    lag: float
    scale: float
    target: float
    planned: Dict[str, float] = field(default_factory=dict)
    held_back: bool = False

    KIND: ClassVar[str] = 'trajectory_clock'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'robot': TEXT, 'time': FLOAT, 'lag': FLOAT, 'scale': FLOAT, 'target': FLOAT,
        'planned': FLOATS, 'held_back': BOOL}

    def name(self) -> str:
        """Return ``'<robot>/trajectory_clock'``."""
        return f'{self.robot}/trajectory_clock'

    def level(self) -> str:
        """Return ``'WARN'`` while the arm runs below full speed, else ``'OK'``."""
        return 'WARN' if self.scale < 1.0 else 'OK'

    def text(self) -> str:
        """Return the factor and the lag."""
        return f'{self.robot} at {self.scale:.2f} of its speed, {self.lag:.3f} s behind'


#: a person as the separation monitor tracks one, from the scans: ``persons.<id>.x``, ...
PERSONS = Records(PersonSeen, 'id', x=FLOAT, y=FLOAT, radius=FLOAT, vx=FLOAT, vy=FLOAT)


@dataclass(frozen=True)
class SeparationStatus(_Status):
    """The separation monitor's decision (``/separation_monitor/status``, at every decision).

    Per arm (keyed by its name): ``scale`` the speed factor given, ``stop`` a protective stop
    (the separation is below the protective separation even at rest), ``cause`` why it is
    below 1 (``''``: it is not), ``separation`` the smallest ``S`` to a person seen, m
    (``inf``: none), ``margin`` the smallest ``S - S_p`` at the arm's planned speed, m.
    ``persons``: the persons tracked from the scans; ``fault``: why every arm stops whatever
    the persons (a silent scanner, unusable ranges, the empty cell not taught), ``''`` if none.
    """

    time: float
    scale: Dict[str, float] = field(default_factory=dict)
    stop: Dict[str, bool] = field(default_factory=dict)
    cause: Dict[str, str] = field(default_factory=dict)
    separation: Dict[str, float] = field(default_factory=dict)
    margin: Dict[str, float] = field(default_factory=dict)
    persons: Tuple[PersonSeen, ...] = ()
    fault: str = ''

    KIND: ClassVar[str] = 'separation_monitor'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'time': FLOAT, 'scale': FLOATS, 'stop': FLAGS, 'cause': NAMES, 'separation': FLOATS,
        'margin': FLOATS, 'persons': PERSONS, 'fault': TEXT}

    def level(self) -> str:
        """Return ``'ERROR'`` for a fault, ``'WARN'`` for a stop or a slowed arm, else OK."""
        if self.fault:
            return 'ERROR'
        return 'WARN' if any(self.stop.values()) or any(
            s < 1.0 for s in self.scale.values()) else 'OK'

    def text(self) -> str:
        """Return the fault, or each arm's factor and what it is for."""
        if self.fault:
            return f'every arm stopped: {self.fault}'
        return '; '.join(f'{r} {self.scale[r]:.2f}' + (' stop' if self.stop.get(r) else '')
                         + (f' ({self.cause[r]})' if self.cause.get(r) else '')
                         for r in self.scale) + f'; {len(self.persons)} person(s) seen'


@dataclass(frozen=True)
class PersonTruth(_Status):
    """Where the simulated person really is, against each arm (``/person/truth``, the bridge).

    For the record, the tests and viewers only: no decision reads it. Published at the state
    rate while the cell has a person. Per arm (keyed by its name): ``separation`` the true
    distance between the person's capsules and the arm's, m (``inf`` while the person is
    away); ``margin`` that separation less the protective separation with the true person
    (no intrusion distance, no sensor tolerance: :func:`scara_collab.core.ssm.true_margin`),
    m; ``moving`` the arm moves; ``contact`` the person touches the arm now.
    """

    time: float
    present: bool
    separation: Dict[str, float] = field(default_factory=dict)
    margin: Dict[str, float] = field(default_factory=dict)
    moving: Dict[str, bool] = field(default_factory=dict)
    contact: Dict[str, bool] = field(default_factory=dict)

    KIND: ClassVar[str] = 'person_truth'
    FIELDS: ClassVar[Dict[str, Codec]] = {
        'time': FLOAT, 'present': BOOL, 'separation': FLOATS, 'margin': FLOATS,
        'moving': FLAGS, 'contact': FLAGS}

    def level(self) -> str:
        """Return ``'ERROR'`` while the person touches a moving arm, else ``'OK'``."""
        return 'ERROR' if any(self.contact.get(r) and self.moving.get(r)
                              for r in self.contact) else 'OK'

    def text(self) -> str:
        """Return where the person is against each arm."""
        if not self.present:
            return 'no person in the cell'
        return '; '.join(f'{r} {d:.3f} m (margin {self.margin.get(r, float("inf")):.3f} m)'
                         for r, d in self.separation.items())
