"""What the simulator bridge publishes on sim time, each at its own rate.

``/clock`` (``clock_rate``), ``joint_states`` (``state_rate``),
``conveyor/items`` (``markers_rate``) and the bridge's diagnostics (1 Hz), each on its own grid
of sim time, then what a part of the bridge adds (:meth:`BridgeOutputs.add`: a person's
scans and ground truth): :meth:`BridgeOutputs.publish_due` publishes whatever has fallen due,
in that order, and :meth:`BridgeOutputs.steps_to_next` tells the bridge how far it may step
before the next one (so no publication is stepped over).
"""
import math
from typing import Callable, Dict, List, Tuple

from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from scara_collab.core.model import CellModel
from scara_collab.graph import CLOCK
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.diagnostics import Diagnostics
from scara_collab.sim.cell_sim import CellSim

STATE_QOS = QoSProfile(depth=10)


class BridgeOutputs:
    """The bridge's periodic publications (see the module docstring).

    :param rates: Hz of sim time for ``clock``, ``state`` and ``markers``.
    :param status: returns the bridge's diagnostics message.
    :param on_clock: called right after each ``/clock`` (the line's frontier goes with it).
    """

    def __init__(self, node: Node, cell: CellModel, sim: CellSim, rates: Dict[str, float],
                 status: Callable[[], object], on_clock: Callable[[], None]):
        """Create the publishers; everything is due at once."""
        self.cell, self.sim, self._status, self._on_clock = cell, sim, status, on_clock
        self.periods = {'state': 1.0 / rates['state'], 'clock': 1.0 / rates['clock'],
                        'markers': 1.0 / rates['markers'], 'diagnostics': 1.0}
        self.next = {k: 0.0 for k in self.periods}
        # next = origin + count x period, never a running sum: 0.01 added 200,000 times drifts
        # past the 1e-9 s the grid is matched within, and the states then came 1 ms late
        self._origin = {k: 0.0 for k in self.periods}
        self._count = {k: 0 for k in self.periods}
        self.clock_pub = node.create_publisher(ClockMsg, CLOCK, STATE_QOS)
        self.state_pub = node.create_publisher(JointState, 'joint_states', STATE_QOS)
        self.items_pub = node.create_publisher(MarkerArray, 'conveyor/items', STATE_QOS)
        self.diagnostics = Diagnostics(node)
        self._added: List[Tuple[str, Callable[[], None]]] = []
        self._first: List[Tuple[str, Callable[[], None]]] = []

    def add(self, key: str, rate: float, publish: Callable[[], None],
            first: bool = False) -> None:
        """Publish with ``publish()`` at ``rate`` (Hz of sim time), from now.

        :param first: before the clock of its instant (what a node decides on at that clock
            must be there when the clock comes), else after the others.
        """
        self.periods[key] = 1.0 / rate
        self.next[key] = self._origin[key] = self.sim.time
        self._count[key] = 0
        (self._first if first else self._added).append((key, publish))

    def steps_to_next(self, dt: float) -> int:
        """Return the physics steps (of ``dt`` s) until the next publication falls due (>= 1)."""
        to_next = min(self.next.values()) - self.sim.time
        return max(1, int(math.ceil(to_next / dt - 1e-6)))

    def publish_due(self) -> None:
        """Publish whatever has fallen due by the simulator's time, in the order above."""
        t = self.sim.time + 1e-9
        for key, publish in self._first:
            if t >= self.next[key]:
                publish()
                self._step(key)
        if t >= self.next['clock']:
            self.clock()
            self._step('clock')
            self._on_clock()
        if t >= self.next['state']:
            self.state()
            self._step('state')
        if t >= self.next['markers']:
            items = self.sim.conveyor.items()
            self.items_pub.publish(conv.item_markers(items, self.cell.item_classes,
                                                     self.cell.item_size, self.sim.time))
            self._step('markers')
        if t >= self.next['diagnostics']:
            self.diagnostics.publish(self._status())
            self._step('diagnostics')
        for key, publish in self._added:
            if t >= self.next[key]:
                publish()
                self._step(key)

    def _step(self, key: str) -> None:
        """Move ``key``'s next publication one period on its grid."""
        self._count[key] += 1
        self.next[key] = self._origin[key] + self._count[key] * self.periods[key]

    def publish_all(self) -> None:
        """Publish everything now, and from now on on its grid."""
        for k in self.next:
            self.next[k] = self._origin[k] = self.sim.time
            self._count[k] = 0
        self.publish_due()

    def publish_off_grid(self) -> None:
        """Publish the clock and the state of an instant off their grids (where the run pauses)."""
        for key, publish in (('clock', self.clock), ('state', self.state)):
            if self.next[key] - self.periods[key] < self.sim.time - 1e-9:
                publish()

    def clock(self) -> None:
        """Publish the simulator's time on ``/clock``."""
        self.clock_pub.publish(ClockMsg(clock=conv.to_time(self.sim.time)))

    def state(self) -> None:
        """Publish both arms' joint state now."""
        names, pos, vel, eff = self.sim.joint_state()
        self.state_pub.publish(conv.joint_state(self.sim.time, names, pos, vel, eff))
