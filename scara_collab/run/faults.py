"""Fault injection for the launcher's ``--fault``: lose, delay or make late what a node sends.

Faults are part of normal life in a distributed graph (Fast DDS drops a service response whose
client reader is not matched yet; a loaded machine delays a status; a real cell's joint states
arrive 10-50 ms late). To prove that the graph survives them, the launcher takes ``--fault
SPEC`` (repeatable), each one of:

``drop:<name>:<N>``
    lose the first ``N`` messages a node publishes on topic ``<name>``, or the first ``N``
    responses a node receives from service ``<name>`` (the server did the work, the answer
    never arrives: exactly the Fast DDS loss) (:class:`Drop`);
``delay:<name>:<N>:<seconds>``
    hold them back ``seconds`` (the node's clock: sim time under the launcher) instead
    (:class:`Delay`);
``latency:<name>:<mean>:<jitter>``
    deliver *every* message (or response) late, each by a delay drawn uniformly from
    ``[mean - jitter, mean + jitter]`` seconds of the node's clock (``0 <= jitter <= mean``),
    in the order they were sent: a message is never delivered before the one sent before it
    (:class:`Latency`, :class:`LatencyLine`). The delays come from a generator seeded with the
    name, so a run draws the same delays every time. The late messages wait in one queue per
    name, taken when the node sends the next one and at each step of the node's clock (on sim
    time: each ``/clock``, so a delay ends at the first ``/clock`` at or after it; on wall
    time: a 1 ms timer, armed only while a message waits). A sim clock that stands still (a
    paused simulation: the launcher pauses the bridge at the end of the job) would keep them
    in flight for ever; when it has not moved between two looks 0.25 s (wall) apart, what
    waits is delivered, in order. ``drop`` and ``delay`` entries for the same name take the
    first ``N`` messages; ``latency`` applies to the others.
``loss:<name>:<p>``
    lose each message (or response) with probability ``p`` (:class:`Loss`);
``repeat:<name>:<p>``
    deliver each message twice with probability ``p`` (a retransmission seen twice)
    (:class:`Repeat`). Both draw from a generator seeded with the name, so a run loses and
    repeats the same ones.
``crash:<node>:<sim s>``
    the node of that fully qualified name (``/cell_1/pybullet_bridge``) dies at that sim
    time, at once and without a goodbye: the launcher's supervisor sends SIGKILL to the
    process that runs it (:class:`Crash`; :mod:`scara_collab.run.supervisor`). A crash of the
    bridge also has the bridge pause there (:func:`scara_collab.run.stages.crashes`), so it
    dies at that sim time to the physics step.

``drop@<sim s>``, ``drop@rate:<per s>``
    an item slips from a gripper: at that sim time whatever an arm holds falls free, or each
    carried item slips at a rate of so many per second of carrying (seeded: the same slips
    every run) (:class:`Slip`). Not a message's fault but the world's: the launcher passes it
    to the bridge (``slip_at``, ``slip_rate``), which drops the item in its simulated world;
    where it lands is the conveyor's to track (on the belt it is an item like any other).

Names are fully qualified (``/scara_left/gripper``, ``/scara_left/planner_status``).

Nothing in the nodes knows of this module. The graph builds each node of a run with
:func:`hook` (:meth:`scara_collab.graph.NodeSpec.build`'s ``wrap``: the launcher's child and
container processes, the in-process job of the benchmarks and tests), and the launcher builds
its own node so, when ``--fault`` is given: the node is then an instance of a subclass of its
class whose ``create_publisher`` and ``create_client`` hand back the node's own endpoints,
wrapped where an entry names them (:class:`FaultyPublisher`, :class:`FaultyClient`). Each
node has its own :class:`FaultPlan` (its counts, its random draws, its latency queues on its
own clock), applies the entries that name its publishers and clients and ignores the others,
so the launcher passes one list to every node. A publisher or client that no entry names is
the plain rclpy one, and without ``--fault`` this module is not even imported. Injected faults
are logged once each (a latency once, when it starts).

Example: ``launch_cell.py --fault drop:/scara_left/gripper:2 --fault
delay:/scara_right/planner_status:3:0.5 --fault latency:/joint_states:0.02:0.01``.
"""
from collections import deque
from dataclasses import dataclass
import random
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple, Union
import zlib

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future

from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.sim_timer import SimTimer

FORMS = ('drop:/<name>:<N>, delay:/<name>:<N>:<seconds>, '
         'latency:/<name>:<mean seconds>:<jitter seconds>, loss:/<name>:<p>, '
         'repeat:/<name>:<p>, crash:/<node>:<sim seconds>, drop@<sim seconds> or '
         'drop@rate:<per second>')
#: wall s between looks at a latency queue on wall time (sim time: every /clock instead)
LATENCY_PERIOD = 1e-3
#: wall s between looks at whether a node's sim clock stands still (paused): what is in
#: flight then arrives, as a network's messages would
STAND_STILL_LOOK = 0.25


@dataclass(frozen=True)
class Drop:
    """Lose the first ``count`` messages (or responses)."""

    count: int


@dataclass(frozen=True)
class Delay:
    """Hold the first ``count`` messages (or responses) back ``seconds`` of the node's clock."""

    count: int
    seconds: float


@dataclass(frozen=True)
class Latency:
    """Deliver every message late by ``mean`` ± ``jitter`` seconds (uniform), in order."""

    mean: float
    jitter: float


@dataclass(frozen=True)
class Loss:
    """Lose each message (or response) with probability ``p``."""

    p: float


@dataclass(frozen=True)
class Repeat:
    """Deliver each message (or response) twice with probability ``p``."""

    p: float


@dataclass(frozen=True)
class Crash:
    """The node dies at sim time ``at`` (s): the launcher's supervisor kills its process."""

    at: float


@dataclass(frozen=True)
class Slip:
    """An item slips from a gripper: at sim time ``at`` (s), or at ``rate`` per carried second."""

    at: Optional[float] = None
    rate: float = 0.0


Fault = Union[Drop, Delay, Latency, Loss, Repeat, Crash, Slip]
_KIND = {Drop: 'drop', Delay: 'delay', Latency: 'latency', Loss: 'loss', Repeat: 'repeat',
         Crash: 'crash', Slip: 'drop@'}
_ARITY = {'drop': 3, 'delay': 4, 'latency': 4, 'loss': 3, 'repeat': 3, 'crash': 3}


def kind(fault: Fault) -> str:
    """Return how the entry of ``fault`` is spelled: ``'drop'``, ..., ``'crash'``."""
    return _KIND[type(fault)]


def parse_fault(spec: str) -> Tuple[str, Fault]:
    """Return ``(name, fault)`` of one entry.

    >>> parse_fault('delay:/scara_right/planner_status:3:0.5')
    ('/scara_right/planner_status', Delay(count=3, seconds=0.5))

    :raises ValueError: with the reason.
    """
    if spec.startswith('drop@'):  # the world's: named for the bridge
        return WORLD, _slip(spec)
    parts = spec.split(':')
    name, arity = parts[1] if len(parts) > 1 else '', _ARITY.get(parts[0])
    if arity is None or len(parts) != arity or not name.startswith('/'):
        raise ValueError(f'fault {spec!r}: expected {FORMS} with a fully qualified name')
    try:
        numbers = [float(p) for p in parts[2:]]
    except ValueError:
        numbers = [float('nan')] * (arity - 2)
    if parts[0] == 'latency':
        mean, jitter = numbers
        if not 0 <= jitter <= mean < float('inf'):
            raise ValueError(f'fault {spec!r}: expected latency:/<name>:<mean>:<jitter> in '
                             'seconds with 0 <= jitter <= mean (delays uniform in '
                             '[mean - jitter, mean + jitter])')
        return name, Latency(mean, jitter)
    if parts[0] == 'crash':
        if not 0 <= numbers[0] < float('inf'):
            raise ValueError(f'fault {spec!r}: expected crash:/<node>:<sim seconds >= 0>')
        return name, Crash(numbers[0])
    if parts[0] in ('loss', 'repeat'):
        if not 0 <= numbers[0] <= 1:
            raise ValueError(f'fault {spec!r}: expected {parts[0]}:/<name>:<p> with '
                             '0 <= p <= 1')
        return name, (Loss if parts[0] == 'loss' else Repeat)(numbers[0])
    try:
        count = int(parts[2])
        seconds = float(parts[3]) if parts[0] == 'delay' else 0.0
    except ValueError:
        count, seconds = -1, 0.0
    if count < 0 or not 0 <= seconds < float('inf'):
        raise ValueError(f'fault {spec!r}: expected {FORMS} with a fully qualified name, '
                         'N >= 0 and seconds >= 0')
    return name, (Delay(count, seconds) if parts[0] == 'delay' else Drop(count))


def parse_faults(specs: Sequence[str]) -> Dict[str, List[Fault]]:
    """Parse the entries (see the module docstring): ``{name: [fault, ...]}`` in their order.

    >>> parse_faults(['drop:/a/gripper:2'])['/a/gripper']
    [Drop(count=2)]
    >>> parse_faults(['latency:/joint_states:0.02:0.01'])['/joint_states'][0].jitter
    0.01

    :raises ValueError: an entry that is not one of the forms, a latency whose jitter is
        negative or larger than its mean, a probability outside [0, 1], or a second latency
        for one name.
    """
    out: Dict[str, List[Fault]] = {}
    for spec in specs:
        if not spec:
            continue
        name, fault = parse_fault(spec)
        if isinstance(fault, Latency) and any(isinstance(f, Latency)
                                              for f in out.get(name, ())):
            raise ValueError(f'fault {spec!r}: a second latency for {name}')
        out.setdefault(name, []).append(fault)
    return out


#: the name the world's faults go under (:class:`Slip`: the bridge's simulated world)
WORLD = ''


def _slip(spec: str) -> Slip:
    """Return the slip of ``drop@<sim s>`` or ``drop@rate:<per s>``.

    >>> _slip('drop@12.5'), _slip('drop@rate:0.05')
    (Slip(at=12.5, rate=0.0), Slip(at=None, rate=0.05))

    :raises ValueError: with the reason.
    """
    text = spec[len('drop@'):]
    try:
        if text.startswith('rate:'):
            rate = float(text[len('rate:'):])
            if 0.0 <= rate < float('inf'):
                return Slip(rate=rate)
        else:
            at = float(text)
            if 0.0 <= at < float('inf'):
                return Slip(at=at)
    except ValueError:
        pass
    raise ValueError(f'fault {spec!r}: expected drop@<sim seconds >= 0> or '
                     'drop@rate:<slips per second of carrying >= 0>')


def slips(specs: Sequence[str]) -> Tuple[List[float], float]:
    """Return the slips of ``specs``: their sim times, sorted, and the rate (the largest).

    >>> slips(['drop@30', 'drop@12.5', 'drop@rate:0.1', 'drop:/a/gripper:1'])
    ([12.5, 30.0], 0.1)
    """
    found = [f for f in parse_faults(specs).get(WORLD, ()) if isinstance(f, Slip)]
    return sorted(f.at for f in found if f.at is not None), max((f.rate for f in found),
                                                                default=0.0)


def crashes(specs: Sequence[str]) -> Dict[str, float]:
    """Return the crashes of ``specs``: ``{fully qualified node name: sim s}`` (the first each).

    >>> crashes(['crash:/cell_1/pybullet_bridge:35', 'drop:/a/gripper:1'])
    {'/cell_1/pybullet_bridge': 35.0}
    """
    return {name: next(f.at for f in faults if isinstance(f, Crash))
            for name, faults in parse_faults(specs).items()
            if any(isinstance(f, Crash) for f in faults)}


def node_entries(specs: Sequence[str]) -> List[str]:
    """Return the entries the nodes apply themselves: all but the crashes (the supervisor's).

    >>> node_entries(['crash:/pybullet_bridge:3', 'drop:/a/gripper:1', ''])
    ['drop:/a/gripper:1']
    """
    return [s for s in specs if s and not isinstance(parse_fault(s)[1], (Crash, Slip))]


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


class FaultPlan:
    """The faults one node injects; :meth:`next` says what happens to the next message.

    :param specs: the ``--fault`` entries (see :func:`parse_faults`); crashes are not the
        node's business and are left out.
    """

    def __init__(self, specs: Sequence[str] = ()):
        """Parse ``specs``; nothing is injected yet."""
        self.faults: Dict[str, Tuple[Fault, ...]] = {
            name: kept for name, faults in parse_faults(specs).items()
            if (kept := tuple(f for f in faults if not isinstance(f, Crash)))}
        #: per name, how many messages each of its faults still takes (a drop's or a delay's)
        self._left: Dict[str, List[int]] = {
            name: [getattr(f, 'count', 0) for f in faults] for name, faults in self.faults.items()}
        self.injected: Dict[str, int] = {}
        self.latency: Dict[str, LatencyLine] = {
            name: LatencyLine(name, f.mean, f.jitter)
            for name, faults in self.faults.items() for f in faults if isinstance(f, Latency)}
        self._lines: Dict[str, _LineDelivery] = {}  # name -> its queue's delivery, once used
        self._chance = {name: random.Random(zlib.crc32(b'chance' + name.encode('utf-8')))
                        for name, faults in self.faults.items()
                        if any(isinstance(f, (Loss, Repeat)) for f in faults)}

    def names(self, name: str) -> bool:
        """Return True if an entry names ``name`` (a fully qualified topic or service)."""
        return name in self.faults

    def next(self, name: str) -> Optional[Fault]:
        """Return the fault that takes the next message of ``name``, or None (deliver).

        A drop, a delay, a loss or a repeat; a latency is not decided here
        (:meth:`deliver` puts the message in its line).
        """
        left = self._left.get(name, ())
        for k, fault in enumerate(self.faults.get(name, ())):
            if left[k] > 0:
                left[k] -= 1
                self.injected[name] = self.injected.get(name, 0) + 1
                return fault
            if isinstance(fault, (Loss, Repeat)) and self._chance[name].random() < fault.p:
                self.injected[name] = self.injected.get(name, 0) + 1
                return fault
        return None

    def deliver(self, node: Node, name: str, action: Callable[[], None]) -> None:
        """Run ``action`` (a publish, a response's delivery) unless the plan drops or delays it.

        :param node: the node whose clock times a delay or a latency, and whose log says so.
        """
        fault = self.next(name)
        if fault is None:
            line = self.latency.get(name)
            if line is None:
                action()
                return
            delivery = self._lines.get(name)
            if delivery is None:
                node.get_logger().warning(
                    f'fault injection: latency {name} by {line.mean:g} +- {line.jitter:g} s on '
                    'every message, in order')
                delivery = self._lines[name] = _LineDelivery(node, line)
            self.injected[name] = self.injected.get(name, 0) + 1
            delivery.put(action)
            return
        chance = next((f for f in self.faults[name] if isinstance(f, (Loss, Repeat))), None)
        if chance is None:
            node.get_logger().warning(f'fault injection: {kind(fault)} {name}' + (
                f' by {fault.seconds:g} s' if isinstance(fault, Delay) else ''))
        elif self.injected[name] == 1:  # said once, of the name's first chance: it goes on
            node.get_logger().warning(f'fault injection: {kind(chance)} {name}, each message '
                                      f'with probability {chance.p:g}')
        if isinstance(fault, Delay):
            _Later(node, fault.seconds, action)
        elif isinstance(fault, Repeat):
            action()
            action()

    def publisher(self, node: Node, publisher):
        """Return ``publisher`` itself, or wrapped (:class:`FaultyPublisher`) if named."""
        if not self.names(publisher.topic_name):
            return publisher
        return FaultyPublisher(node, self, publisher)

    def client(self, node: Node, client):
        """Return ``client`` itself, or wrapped (:class:`FaultyClient`) if named."""
        name = node.resolve_service_name(client.srv_name)  # a client keeps the name it was given
        if not self.names(name):
            return client
        return FaultyClient(node, self, client, name)


class FaultyPublisher:
    """A publisher whose messages go through a node's fault plan (the publisher's API).

    :meth:`publish` goes through the plan; anything else is the wrapped publisher's.
    """

    def __init__(self, node: Node, plan: FaultPlan, publisher):
        """Wrap ``publisher`` of ``node``; its topic name selects the plan entries."""
        self.node, self.plan, self.publisher = node, plan, publisher
        self.name = publisher.topic_name

    def __getattr__(self, attr: str):
        """Return the wrapped publisher's attribute (``topic_name``, counts, ``handle``)."""
        if attr == 'publisher':  # not set yet: no recursion
            raise AttributeError(attr)
        return getattr(self.publisher, attr)

    def publish(self, msg) -> None:
        """Publish ``msg`` now, later, or never (see :class:`FaultPlan`)."""
        self.plan.deliver(self.node, self.name, lambda: self.publisher.publish(msg))


class _Response(Future):
    """A response future that a repeat completes twice: its done callbacks run again."""

    def __init__(self):
        super().__init__()
        self._all: list = []

    def add_done_callback(self, callback) -> None:
        self._all.append(callback)
        super().add_done_callback(callback)

    def deliver(self, response) -> None:
        """Complete with ``response``; a second time, run the done callbacks again."""
        if self.done():
            for callback in self._all:
                callback(self)
            return
        self.set_result(response)


class FaultyClient:
    """A service client whose responses go through a node's fault plan (the client's API).

    :meth:`call_async` returns a future of its own, completed when the plan delivers the
    response (never, when it loses it); anything else is the wrapped client's.
    """

    def __init__(self, node: Node, plan: FaultPlan, client, name: str):
        """Wrap ``client`` of ``node``, the service's fully qualified ``name``."""
        self.node, self.plan, self.client, self.name = node, plan, client, name

    def __getattr__(self, attr: str):
        """Return the wrapped client's attribute (``srv_name``, ``service_is_ready``, ...)."""
        if attr == 'client':  # not set yet: no recursion
            raise AttributeError(attr)
        return getattr(self.client, attr)

    def call_async(self, request) -> Future:
        """Send ``request``; return the future its (faulty) response completes."""
        outer = _Response()

        def done(inner: Future) -> None:
            if inner.cancelled():
                outer.cancel()
                return
            exc = inner.exception()
            if exc is not None:
                outer.set_exception(exc)
                return
            response = inner.result()
            if response is None:
                outer.set_result(None)
                return
            self.plan.deliver(self.node, self.name, lambda: outer.deliver(response))
        self.client.call_async(request).add_done_callback(done)
        return outer


def with_faults(cls: type, specs: Sequence[str]) -> type:
    """Return a subclass of the node class ``cls`` that injects the faults ``specs`` names.

    Each instance has its own :class:`FaultPlan` (:attr:`fault_plan`), made before the node
    is; ``create_publisher`` and ``create_client`` return the node's endpoints through
    :meth:`FaultPlan.publisher` and :meth:`FaultPlan.client`.

    :raises ValueError: a malformed entry (before any node is built).
    """
    specs = list(specs)
    parse_faults(specs)

    class Faulty(cls):
        def __init__(self, *args, **kwargs):
            self.fault_plan = FaultPlan(specs)
            super().__init__(*args, **kwargs)
            if self.fault_plan.faults:
                self.get_logger().warning(f'fault injection on: {sorted(self.fault_plan.faults)}')

        def create_publisher(self, *args, **kwargs):
            return self.fault_plan.publisher(self, super().create_publisher(*args, **kwargs))

        def create_client(self, *args, **kwargs):
            return self.fault_plan.client(self, super().create_client(*args, **kwargs))

    Faulty.__name__ = Faulty.__qualname__ = cls.__name__
    Faulty.__doc__ = cls.__doc__
    return Faulty


def hook(specs: Sequence[str]) -> Callable[[type], type]:
    """Return the wrap that builds nodes with the faults ``specs`` (:func:`with_faults`).

    What the graph's builders pass as :meth:`scara_collab.graph.NodeSpec.build`'s ``wrap``.

    :raises ValueError: a malformed entry.
    """
    specs = node_entries(specs)
    return lambda cls: with_faults(cls, specs)


def plan_of(node: Node) -> Optional[FaultPlan]:
    """Return the fault plan of a node built with :func:`with_faults` (None: no faults)."""
    return getattr(node, 'fault_plan', None)
