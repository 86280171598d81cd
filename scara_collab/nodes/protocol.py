"""The job protocol: every status the nodes exchange, typed, in one module.

Each status is a frozen dataclass with ``to_msg()`` and ``from_msg()`` on the standard
``diagnostic_msgs/DiagnosticStatus`` (``name``, ``level``, a readable ``message`` and one
key-value per field). No other module formats or parses these key-values: a node builds the
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
================================  ==================  =======================================

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
import functools
import json
import math
import numbers
from typing import ClassVar, Dict, get_type_hints, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from scara_collab.core import line, sorting
from scara_collab.core.moves import EXECUTION_STATES, move_id, PLANNER_STATES

LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
          'ERROR': DiagnosticStatus.ERROR, 'STALE': DiagnosticStatus.STALE}


class ProtocolError(ValueError):
    """A status message does not follow the protocol; the text says why."""


def _encode(value) -> str:
    if value is None:
        return ''
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))  # round-trips exactly (numpy floats too)
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, separators=(',', ':'))
    return str(value)


def _decode(text: str, kind, key: str):
    optional = getattr(kind, '__args__', None)
    if optional is not None and type(None) in optional:  # Optional[X]
        if text == '':
            return None
        kind = next(k for k in optional if k is not type(None))
    origin = getattr(kind, '__origin__', kind)
    try:
        if origin is bool:
            if text not in ('true', 'false'):
                raise ValueError(text)
            return text == 'true'
        if origin is int:
            return int(text)
        if origin is float:
            v = float(text)
            if math.isnan(v):
                raise ValueError('NaN')
            return v
        if origin in (dict, list, tuple):
            v = json.loads(text)
            return tuple(v) if origin is tuple else v
        return text
    except (ValueError, TypeError, json.JSONDecodeError) as exc:
        raise ProtocolError(f'{key}={text!r} is not a valid {getattr(kind, "__name__", kind)}'
                            f' ({exc})') from None


@functools.lru_cache(maxsize=None)
def _hints(cls) -> Dict[str, object]:
    """Return the field types of a status class (resolved once: it is on every message's path)."""
    return get_type_hints(cls)


class _Status:
    """Fields <-> ``DiagnosticStatus`` key-values (one per field, typed by the annotations)."""

    #: the ``DiagnosticStatus.name`` suffix or fixed name of this status
    KIND: ClassVar[str] = ''
    #: ``(field, allowed values)`` checked on construction, or None
    CHOICES: ClassVar[Optional[Tuple[str, tuple]]] = None

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
        """Return the status as a ``DiagnosticStatus``."""
        msg = DiagnosticStatus(level=LEVELS[self.level()], name=self.name(),
                               message=self.text())
        msg.values = [KeyValue(key=f.name, value=_encode(getattr(self, f.name)))
                      for f in fields(self)]
        return msg

    @classmethod
    def from_msg(cls, msg: DiagnosticStatus):
        """Parse a ``DiagnosticStatus`` built by :meth:`to_msg`.

        :raises ProtocolError: a missing or malformed field.
        """
        values = {kv.key: kv.value for kv in msg.values}
        hints = _hints(cls)
        kwargs = {}
        for f in fields(cls):
            if f.name not in values:
                if f.default is not MISSING or f.default_factory is not MISSING:
                    continue  # an optional field
                raise ProtocolError(f'{cls.__name__}: no {f.name!r} in {sorted(values)}')
            kwargs[f.name] = _decode(values[f.name], hints[f.name], f.name)
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise ProtocolError(f'{cls.__name__}: {exc}') from None

    def values(self) -> Dict[str, object]:
        """Return the fields as a plain dict (for JSON summaries)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


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
    (the move is aborted); ``cleared``: the stop was released, or the guard answers again.
    """

    time: float
    stamp: Optional[float] = None
    by: str = ''

    KIND: ClassVar[str] = 'execution'
    CHOICES: ClassVar[Tuple[str, tuple]] = ('state', EXECUTION_STATES)

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
        """Seconds the bridge started after the requested stamp (0 if on time or unstamped)."""
        if self.state != 'accepted' or not self.stamp or self.start is None:
            return 0.0
        return max(0.0, self.start - self.stamp)


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

    KIND: ClassVar[str] = 'automation_manager'

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
    the frontier, all told; ``items``: the handoffs of the last seconds before the frontier,
    each ``[id, class, y, crossing time]`` (repeated from message to message, so a lost
    message is made up for); ``belt``: the items resting on the sender's belt at the
    frontier, each ``[id, class, x, y]`` (what its section still carries should it die;
    :mod:`scara_collab.core.line`).
    """

    cell: int
    frontier: float
    handed: int
    items: list
    belt: list = field(default_factory=list)

    KIND: ClassVar[str] = 'line_handoff'

    def __post_init__(self):  # noqa: D105 (the checks the message's fields must pass)
        if not math.isfinite(self.frontier):
            raise ValueError(f'frontier must be a finite sim time, got {self.frontier!r}')
        lists = isinstance(self.items, list) and isinstance(self.belt, list)
        if self.handed < 0 or not lists:
            raise ValueError(f'handed {self.handed!r} < 0, or items or belt not a list')

    def handoffs(self) -> list:
        """Return ``items`` as :class:`~scara_collab.core.line.Handoff` records.

        :raises ProtocolError: an item that is not ``[id, class, y, time]``.
        """
        return self._read(line.Handoff, self.items)

    def on_belt(self) -> list:
        """Return ``belt`` as :class:`~scara_collab.core.line.OnBelt` records.

        :raises ProtocolError: an item that is not ``[id, class, x, y]``.
        """
        return self._read(line.OnBelt, self.belt)

    def _read(self, record, values: list) -> list:
        try:
            return [record.from_list(v) for v in values]
        except ValueError as exc:
            raise ProtocolError(f'LineHandoff from cell {self.cell}: {exc}') from None

    def text(self) -> str:
        """Return the frontier and the count."""
        return (f'cell {self.cell} at sim t={self.frontier:.3f} s, {self.handed} handed on, '
                f'{len(self.items)} in this message')
