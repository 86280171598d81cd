"""Take the simulator's messages in the order of its clock, whatever order they arrive in.

At each ``/clock`` instant the bridge publishes the clock first, then the state, the item
markers and the item events up to that instant (and a state half-way to the next clock). A
node that acts on its clock (the automation manager's tick) therefore sees, at sim time t,
what the bridge published before t. DDS keeps no order between topics, though: as separate
processes, the state of instant t now and then arrives before the clock of t, and the tick at
t sees it (seen: the job's offer at 7.30 s planned from the state of 7.30 s in one run, of
7.29 s in the next; README, *Repeatable runs*).

:class:`ClockOrder` restores the order. A message stamped more than half a clock step ahead
of the node's clock belongs to a ``/clock`` still to come (with ``/joint_states`` at twice the
clock's rate, as configured, the half-way state is the last one that may come before it): it
is held and handed on right after that clock's callbacks (the tick) have run, as if it had
come after its clock. Anything else is handed on at once. The clock step is the last jump of
the node's sim clock.
"""
import math
from typing import Callable, List, Tuple

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node

from scara_collab.nodes.runner import guarded

#: s: slack on stamp comparisons (stamps are whole nanoseconds)
_EPS = 1e-6


class ClockOrder:
    """Hand on messages in clock order (see the module docstring); pure, no ROS.

    >>> order, seen = ClockOrder(), []
    >>> order.advance(0.02); order.advance(0.04)  # the clock is at 0.04 s, a step of 0.02 s
    >>> order.admit(0.05, lambda: seen.append('state 0.05'))  # half-way: now
    >>> order.admit(0.06, lambda: seen.append('state 0.06'))  # ahead of its clock: held
    >>> seen
    ['state 0.05']
    >>> order.advance(0.06)  # after the tick at 0.06 s
    >>> seen
    ['state 0.05', 'state 0.06']
    """

    def __init__(self):
        """No clock yet: nothing is held until the clock has stepped twice."""
        self.now = None
        self.step = math.inf
        self.held: List[Tuple[float, Callable[[], None]]] = []

    def admit(self, stamp: float, deliver: Callable[[], None]) -> None:
        """Deliver now, or hold until the clock reaches ``stamp`` (s) if it is ahead of it."""
        if self.now is not None and stamp > self.now + 0.5 * self.step + _EPS:
            self.held.append((stamp, deliver))
        else:
            deliver()

    def advance(self, now: float) -> None:
        """Deliver what is due now that the clock is at ``now`` (s) and its callbacks have run."""
        if self.now is not None and now > self.now:
            self.step = now - self.now
        self.now = now
        due = [h for h in self.held if h[0] <= now + _EPS]
        if due:
            self.held = [h for h in self.held if h[0] > now + _EPS]
            for _, deliver in due:  # in arrival order
                deliver()


def clock_order(node: Node) -> ClockOrder:
    """Return a :class:`ClockOrder` advanced by ``node``'s sim clock.

    Create it after the node's sim timers (:func:`scara_collab.nodes.sim_timer.every`) and
    before it joins the lockstep: jump callbacks run in the order they were made, so held
    messages come after the tick and before the node answers the clock. Off sim time it
    holds nothing.
    """
    order = ClockOrder()
    if not node.get_parameter('use_sim_time').value:
        return order
    clock = node.get_clock()
    release = guarded(node, lambda _jump: order.advance(clock.now().nanoseconds * 1e-9))
    order.handle = clock.create_jump_callback(
        JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None,
                      on_clock_change=False), post_callback=release)
    return order
