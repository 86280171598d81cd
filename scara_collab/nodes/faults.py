"""Fault injection: lose or delay the first messages of a topic or responses of a service.

Faults are part of normal life in a distributed graph (Fast DDS drops a service response whose
client reader is not matched yet; a loaded machine delays a status). To prove that the graph
survives them, every node takes the parameter ``faults`` (string array; the launcher's
``--fault SPEC``), each entry one of:

``drop:<name>:<N>``
    lose the first ``N`` messages published on topic ``<name>`` by this node, or the first
    ``N`` responses this node receives from service ``<name>`` (the server did the work, the
    answer never arrives: exactly the Fast DDS loss);
``delay:<name>:<N>:<seconds>``
    hold them back ``seconds`` (the node's clock: sim time under the launcher) instead.

Names are fully qualified (``/scara_left/gripper``, ``/scara_left/planner_status``). A node
applies the entries that name its own publishers and clients and ignores the others, so the
launcher can pass one list to every node. Injected faults are logged once each.

Example: ``launch_cell.py --fault drop:/scara_left/gripper:2 --fault
delay:/scara_right/planner_status:3:0.5``.
"""
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node

KINDS = ('drop', 'delay')


@dataclass
class Fault:
    """One injected fault: ``kind`` (drop | delay), how many are left, the delay (s)."""

    kind: str
    remaining: int
    delay: float = 0.0


def parse_faults(specs: Sequence[str]) -> Dict[str, List[Fault]]:
    """Parse ``drop:<name>:<N>`` / ``delay:<name>:<N>:<s>`` entries (see the module docstring).

    >>> parse_faults(['drop:/a/gripper:2'])['/a/gripper'][0].remaining
    2

    :raises ValueError: an entry that is not one of the two forms.
    """
    out: Dict[str, List[Fault]] = {}
    for spec in specs:
        if not spec:
            continue
        parts = spec.split(':')
        kind = parts[0]
        ok = (kind == 'drop' and len(parts) == 3) or (kind == 'delay' and len(parts) == 4)
        try:
            n = int(parts[2]) if ok else -1
            delay = float(parts[3]) if kind == 'delay' and ok else 0.0
        except ValueError:
            ok = False
        if not ok or n < 0 or delay < 0 or not parts[1].startswith('/'):
            raise ValueError(f'fault {spec!r}: expected drop:/<name>:<N> or '
                             'delay:/<name>:<N>:<seconds> with a fully qualified name')
        out.setdefault(parts[1], []).append(Fault(kind, n, delay))
    return out


class FaultPlan:
    """The faults one node injects; :meth:`next` says what happens to the next message."""

    def __init__(self, specs: Sequence[str] = ()):
        """Parse ``specs`` (see :func:`parse_faults`); nothing is injected yet."""
        self.faults = parse_faults(specs)
        self.injected: Dict[str, int] = {}

    def next(self, name: str) -> Optional[Tuple[str, float]]:
        """Return ``('drop', 0)``, ``('delay', s)`` or None (deliver) for the next on ``name``."""
        for fault in self.faults.get(name, ()):
            if fault.remaining > 0:
                fault.remaining -= 1
                self.injected[name] = self.injected.get(name, 0) + 1
                return fault.kind, fault.delay
        return None


def declare_faults(node: Node) -> FaultPlan:
    """Declare the ``faults`` parameter on ``node`` and return its plan.

    :raises ValueError: a malformed entry (the node refuses to start, with the reason).
    """
    if not node.has_parameter('faults'):
        node.declare_parameter('faults', [''], ParameterDescriptor(
            type=ParameterType.PARAMETER_STRING_ARRAY,
            description='fault injection: drop:/<name>:<N>, delay:/<name>:<N>:<seconds>'))
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


def deliver(node: Node, plan: FaultPlan, name: str, action: Callable[[], None]) -> None:
    """Run ``action`` (a publish or a response handler) unless ``plan`` drops or delays it."""
    decision = plan.next(name)
    if decision is None:
        action()
        return
    kind, delay = decision
    node.get_logger().warning(f'fault injection: {kind} {name}'
                              + (f' by {delay:g} s' if kind == 'delay' else ''))
    if kind == 'delay':
        _Later(node, delay, action)


class FaultyPublisher:
    """A publisher whose messages go through the node's fault plan (same ``publish`` API)."""

    def __init__(self, node: Node, plan: FaultPlan, publisher):
        """Wrap ``publisher`` of ``node``; its topic name selects the plan entries."""
        self.node, self.plan, self.publisher = node, plan, publisher
        self.name = publisher.topic_name

    def publish(self, msg) -> None:
        """Publish ``msg`` now, later, or never (see :class:`FaultPlan`)."""
        if not self.plan.faults:
            self.publisher.publish(msg)
            return
        deliver(self.node, self.plan, self.name, lambda: self.publisher.publish(msg))


def call_with_faults(node: Node, plan: FaultPlan, client, request,
                     on_response: Callable[[object], None]) -> None:
    """``client.call_async(request)``; ``on_response(response)`` unless the plan loses it."""
    future = client.call_async(request)
    name = client.srv_name

    def done(f) -> None:
        try:
            response = f.result()
        except Exception:  # noqa: B902 - a cancelled or failed call is a lost response
            return
        if response is not None:
            deliver(node, plan, name, lambda: on_response(response))
    future.add_done_callback(done)
