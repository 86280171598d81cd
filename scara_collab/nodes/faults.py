"""Fault injection: lose, delay or make late the messages of a topic or responses of a service.

Faults are part of normal life in a distributed graph (Fast DDS drops a service response whose
client reader is not matched yet; a loaded machine delays a status; a real cell's joint states
arrive 10-50 ms late). To prove that the graph survives them, every node takes the parameter
``faults`` (string array; the launcher's ``--fault SPEC``), each entry one of:

``drop:<name>:<N>``
    lose the first ``N`` messages published on topic ``<name>`` by this node, or the first
    ``N`` responses this node receives from service ``<name>`` (the server did the work, the
    answer never arrives: exactly the Fast DDS loss);
``delay:<name>:<N>:<seconds>``
    hold them back ``seconds`` (the node's clock: sim time under the launcher) instead;
``latency:<name>:<mean>:<jitter>``
    deliver *every* message (or response) late, each by a delay drawn uniformly from
    ``[mean - jitter, mean + jitter]`` seconds of the node's clock (``0 <= jitter <= mean``),
    in the order they were sent: a message is never delivered before the one sent before it
    (:class:`LatencyLine`). The delays come from a generator seeded with the name, so a run
    draws the same delays every time. The late messages wait in one queue per name, taken
    when the node sends the next one and at each step of the node's clock (on sim time: each
    ``/clock``, so a delay ends at the first ``/clock`` at or after it; on wall time: a 1 ms
    timer, armed only while a message waits). A sim clock that stands still (a paused
    simulation: the launcher pauses the bridge at the end of the job) would keep them in
    flight for ever; when it has not moved between two looks 0.25 s (wall) apart, what waits
    is delivered, in order. ``drop`` and ``delay`` entries for the same name take the first
    ``N`` messages; ``latency`` applies to the others.
``loss:<name>:<p>``
    lose each message (or response) with probability ``p``;
``repeat:<name>:<p>``
    deliver each message twice with probability ``p`` (a retransmission seen twice). Both
    draw from a generator seeded with the name, so a run loses and repeats the same ones.
``crash:<node>:<sim s>``
    the node of that fully qualified name (``/cell_1/pybullet_bridge``; the bridge only) dies
    at that sim time, at once and without a goodbye, as a process that is killed (exit 70).

Names are fully qualified (``/scara_left/gripper``, ``/scara_left/planner_status``). A node
applies the entries that name its own publishers and clients and ignores the others, so the
launcher can pass one list to every node. A publisher that no entry names publishes directly,
at no cost. Injected faults are logged once each (a latency once, when it starts).

Example: ``launch_cell.py --fault drop:/scara_left/gripper:2 --fault
delay:/scara_right/planner_status:3:0.5 --fault latency:/joint_states:0.02:0.01``.
"""
from collections import deque
from dataclasses import dataclass
import random
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple
import zlib

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from scara_collab.nodes.guarded import guarded

KINDS = ('drop', 'delay', 'latency', 'loss', 'repeat', 'crash')
FORMS = ('drop:/<name>:<N>, delay:/<name>:<N>:<seconds>, '
         'latency:/<name>:<mean seconds>:<jitter seconds>, loss:/<name>:<p>, '
         'repeat:/<name>:<p> or crash:/<node>:<sim seconds>')
CRASH_EXIT = 70  # the exit status of a node that a crash fault kills
_CHANCE = ('loss', 'repeat')  # a probability per message
#: wall s between looks at a latency queue on wall time (sim time: every /clock instead)
LATENCY_PERIOD = 1e-3
#: wall s between looks at whether a node's sim clock stands still (paused): what is in
#: flight then arrives, as a network's messages would
STAND_STILL_LOOK = 0.25


@dataclass
class Fault:
    """One injected fault: ``kind`` (drop | delay | latency), how many are left, the delay (s).

    A latency has no count (``remaining`` 0): ``delay`` is its mean, ``jitter`` its half-width.
    """

    kind: str
    remaining: int
    delay: float = 0.0
    jitter: float = 0.0


def _parse_one(spec: str) -> Tuple[str, Fault]:
    """Return ``(name, fault)`` of one entry; :raises ValueError: with the reason."""
    parts = spec.split(':')
    kind = parts[0]
    arity = {'drop': 3, 'delay': 4, 'latency': 4, 'loss': 3, 'repeat': 3, 'crash': 3}.get(kind)
    if arity is None or len(parts) != arity or not parts[1].startswith('/'):
        raise ValueError(f'fault {spec!r}: expected {FORMS} with a fully qualified name')
    try:
        numbers = [float(p) for p in parts[2:]]
    except ValueError:
        numbers = [float('nan')]
    if kind == 'latency':
        mean, jitter = (numbers + [float('nan')])[:2]
        if not 0 <= jitter <= mean < float('inf'):
            raise ValueError(f'fault {spec!r}: expected latency:/<name>:<mean>:<jitter> in '
                             'seconds with 0 <= jitter <= mean (delays uniform in '
                             '[mean - jitter, mean + jitter])')
        return parts[1], Fault(kind, 0, mean, jitter)
    if kind == 'crash':
        if not 0 <= numbers[0] < float('inf'):
            raise ValueError(f'fault {spec!r}: expected crash:/<node>:<sim seconds >= 0>')
        return parts[1], Fault(kind, 0, numbers[0])
    if kind in _CHANCE:
        if not 0 <= numbers[0] <= 1:
            raise ValueError(f'fault {spec!r}: expected {kind}:/<name>:<p> with 0 <= p <= 1')
        return parts[1], Fault(kind, 0, numbers[0])
    try:
        n = int(parts[2])
        delay = float(parts[3]) if kind == 'delay' else 0.0
    except ValueError:
        n, delay = -1, 0.0
    if n < 0 or not 0 <= delay < float('inf'):
        raise ValueError(f'fault {spec!r}: expected {FORMS} with a fully qualified name, '
                         'N >= 0 and seconds >= 0')
    return parts[1], Fault(kind, n, delay)


def parse_faults(specs: Sequence[str]) -> Dict[str, List[Fault]]:
    """Parse the entries (see the module docstring).

    >>> parse_faults(['drop:/a/gripper:2'])['/a/gripper'][0].remaining
    2
    >>> parse_faults(['latency:/joint_states:0.02:0.01'])['/joint_states'][0].jitter
    0.01

    :raises ValueError: an entry that is not one of the forms, a latency whose jitter is
        negative or larger than its mean, or a probability outside [0, 1].
    """
    out: Dict[str, List[Fault]] = {}
    for spec in specs:
        if not spec:
            continue
        name, fault = _parse_one(spec)
        if fault.kind == 'latency' and any(f.kind == 'latency' for f in out.get(name, ())):
            raise ValueError(f'fault {spec!r}: a second latency for {name}')
        out.setdefault(name, []).append(fault)
    return out


class LatencyLine:
    """The late messages of one name, in order; each delay uniform in ``mean`` ± ``jitter``.

    Plain bookkeeping on the times it is given (no clock of its own): :meth:`push` an item at
    ``now``, :meth:`pop_due` the items whose time has come. An item is due at
    ``max(the previous item's due time, now + delay)``, so items leave in the order they came.

    >>> line = LatencyLine('/joint_states', 0.02, 0.0)
    >>> line.push(1.0, 'a'), line.push(1.005, 'b')
    (1.02, 1.025)
    >>> line.pop_due(1.02), line.pop_due(1.03)
    (['a'], ['b'])

    :param name: the topic or service; seeds the delays (the same every run).
    :param mean: s, >= 0; :param jitter: s, in ``[0, mean]``.
    """

    def __init__(self, name: str, mean: float, jitter: float):
        """Start empty, the generator seeded with ``name``."""
        self.name, self.mean, self.jitter = name, float(mean), float(jitter)
        self.rng = random.Random(zlib.crc32(name.encode('utf-8')))
        self.queue: Deque[Tuple[float, object]] = deque()
        self.last_due = float('-inf')
        self.sent = 0

    def draw(self) -> float:
        """Return the next delay, s: uniform in ``[mean - jitter, mean + jitter]``, >= 0."""
        return max(0.0, self.rng.uniform(self.mean - self.jitter, self.mean + self.jitter))

    def push(self, now: float, item) -> float:
        """Queue ``item`` sent at ``now`` (s); return when it is due (s)."""
        self.last_due = max(self.last_due, now + self.draw())
        self.queue.append((self.last_due, item))
        self.sent += 1
        return self.last_due

    def pop_due(self, now: float) -> list:
        """Remove and return the items due at ``now`` (s), oldest first."""
        out = []
        while self.queue and self.queue[0][0] <= now + 1e-12:
            out.append(self.queue.popleft()[1])
        return out

    def __len__(self) -> int:
        """Return how many items wait."""
        return len(self.queue)


class FaultPlan:
    """The faults one node injects; :meth:`next` says what happens to the next message."""

    def __init__(self, specs: Sequence[str] = ()):
        """Parse ``specs`` (see :func:`parse_faults`); nothing is injected yet."""
        self.faults = parse_faults(specs)
        self.injected: Dict[str, int] = {}
        self.latency: Dict[str, LatencyLine] = {
            name: LatencyLine(name, f.delay, f.jitter)
            for name, faults in self.faults.items() for f in faults if f.kind == 'latency'}
        self._lines: Dict[str, '_LineDelivery'] = {}  # name -> its queue's delivery, once used
        self._chance = {name: random.Random(zlib.crc32(b'chance' + name.encode('utf-8')))
                        for name, faults in self.faults.items()
                        if any(f.kind in _CHANCE for f in faults)}

    def crash_time(self, node: str) -> Optional[float]:
        """Return the sim time the node of fully qualified name ``node`` is to die, or None."""
        return next((f.delay for f in self.faults.get(node, ()) if f.kind == 'crash'), None)

    def next(self, name: str) -> Optional[Tuple[str, float]]:
        """Return ``('drop', 0)``, ``('delay', s)``, ``('repeat', 0)`` or None (deliver).

        A loss is a drop. A latency is not decided here (:func:`deliver` puts the message in
        its line).
        """
        for fault in self.faults.get(name, ()):
            if fault.remaining > 0:
                fault.remaining -= 1
                self.injected[name] = self.injected.get(name, 0) + 1
                return fault.kind, fault.delay
            if fault.kind in _CHANCE and self._chance[name].random() < fault.delay:
                self.injected[name] = self.injected.get(name, 0) + 1
                return ('drop' if fault.kind == 'loss' else 'repeat'), 0.0
        return None


def declare_faults(node: Node) -> FaultPlan:
    """Declare the ``faults`` parameter on ``node`` and return its plan.

    :raises ValueError: a malformed entry (the node refuses to start, with the reason).
    """
    if not node.has_parameter('faults'):
        node.declare_parameter('faults', [''], ParameterDescriptor(
            type=ParameterType.PARAMETER_STRING_ARRAY,
            description=f'fault injection: {FORMS}'))
    plan = FaultPlan(list(node.get_parameter('faults').value or []))
    if plan.faults:
        node.get_logger().warning(f'fault injection on: {sorted(plan.faults)}')
    return plan


class _Later:
    """Run ``action`` once after ``delay`` seconds of the node's clock."""

    def __init__(self, node: Node, delay: float, action: Callable[[], None]):
        self.node, self.action = node, action
        self.timer = node.create_timer(max(delay, 1e-6), self._fire)

    def _fire(self) -> None:
        self.timer.cancel()
        self.node.destroy_timer(self.timer)
        self.action()


class _LineDelivery:
    """Run the actions of one :class:`LatencyLine` when they are due on the node's clock.

    One queue and one look per name, never a timer per message: the line is looked at when
    the next action comes and at every step of the node's clock (on sim time a
    :class:`~scara_collab.nodes.sim_timer.SimTimer` that runs at each ``/clock``, and a
    :data:`STAND_STILL_LOOK` steady timer for a clock that stands still; on wall time a
    :data:`LATENCY_PERIOD` timer, cancelled while nothing waits).
    """

    def __init__(self, node: Node, line: LatencyLine):
        from scara_collab.nodes.sim_timer import SimTimer
        self.line = line
        self._clock = node.get_clock()
        self._timer = None
        self._seen: Optional[int] = None  # ns of the node's clock at the last look
        if node.has_parameter('use_sim_time') and node.get_parameter('use_sim_time').value:
            SimTimer(node, LATENCY_PERIOD, self.take)  # kept by the node
            node.create_timer(STAND_STILL_LOOK, guarded(node, self._look),
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        else:
            self._timer = node.create_timer(LATENCY_PERIOD, guarded(node, self.take))
            self._timer.cancel()

    def _now(self) -> float:
        return self._clock.now().nanoseconds * 1e-9

    def put(self, action: Callable[[], None]) -> None:
        """Queue ``action`` late by the line's next delay (run now if that is due already)."""
        now = self._now()
        self.take(now)  # whatever is due goes first
        self.line.push(now, action)
        self.take(now)
        if self._timer is not None and len(self.line) and self._timer.is_canceled():
            self._timer.reset()

    def _look(self) -> None:
        """Deliver what waits if the node's clock has not moved since the last look."""
        now = self._clock.now().nanoseconds
        if now == self._seen and len(self.line):
            self.take(float('inf'))
        self._seen = now

    def take(self, now: Optional[float] = None) -> None:
        """Run the actions due now, oldest first."""
        for action in self.line.pop_due(self._now() if now is None else now):
            action()
        if self._timer is not None and not len(self.line):
            self._timer.cancel()


def deliver(node: Node, plan: FaultPlan, name: str, action: Callable[[], None]) -> None:
    """Run ``action`` (a publish or a response handler) unless ``plan`` drops or delays it."""
    decision = plan.next(name)
    if decision is None:
        line = plan.latency.get(name)
        if line is None:
            action()
            return
        delivery = plan._lines.get(name)
        if delivery is None:
            node.get_logger().warning(
                f'fault injection: latency {name} by {line.mean:g} +- {line.jitter:g} s on '
                'every message, in order')
            delivery = plan._lines[name] = _LineDelivery(node, line)
        plan.injected[name] = plan.injected.get(name, 0) + 1
        delivery.put(action)
        return
    kind, delay = decision
    chance = next((f for f in plan.faults[name] if f.kind in _CHANCE), None)
    if chance is None:
        node.get_logger().warning(f'fault injection: {kind} {name}'
                                  + (f' by {delay:g} s' if kind == 'delay' else ''))
    elif plan.injected[name] == 1:  # said once: it goes on for every message
        node.get_logger().warning(f'fault injection: {chance.kind} {name}, each message with '
                                  f'probability {chance.delay:g}')
    if kind == 'delay':
        _Later(node, delay, action)
    elif kind == 'repeat':
        action()
        action()


class FaultyPublisher:
    """A publisher whose messages go through the node's fault plan (same ``publish`` API).

    When no entry of the plan names its topic, :meth:`publish` *is* the publisher's own
    ``publish`` (bound at construction): no cost on a hot path such as ``/joint_states``.
    """

    def __init__(self, node: Node, plan: FaultPlan, publisher):
        """Wrap ``publisher`` of ``node``; its topic name selects the plan entries."""
        self.node, self.plan, self.publisher = node, plan, publisher
        self.name = publisher.topic_name
        if self.name not in plan.faults:
            self.publish = publisher.publish  # the plan never changes: publish directly

    @property
    def topic_name(self) -> str:
        """Return the fully qualified topic name (as the publisher's)."""
        return self.name

    def publish(self, msg) -> None:
        """Publish ``msg`` now, later, or never (see :class:`FaultPlan`)."""
        deliver(self.node, self.plan, self.name, lambda: self.publisher.publish(msg))


def call_with_faults(node: Node, plan: FaultPlan, client, request,
                     on_response: Callable[[object], None]) -> None:
    """``client.call_async(request)``; ``on_response(response)`` unless the plan loses it."""
    future = client.call_async(request)
    name = node.resolve_service_name(client.srv_name)  # a client keeps the name it was given

    def done(f) -> None:
        try:
            response = f.result()
        except Exception:  # noqa: B902 - a cancelled or failed call is a lost response
            return
        if response is not None:
            deliver(node, plan, name, lambda: on_response(response))
    future.add_done_callback(done)
