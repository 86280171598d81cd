"""A periodic callback on sim time, run in turn with the node's other callbacks.

An rclpy timer on sim time fires when the node's clock passes its next call. Which thread
notices that is the executor's business: rclpy's ``EventsExecutor`` keeps its timers in a
thread of their own, which queues the call whenever it happens to look, before or after the
messages of the same sim instant. The job's decisions (the automation manager's tick, the
collision monitor's watch) then see a state or not depending on the machine's timing, and two
runs with the same seed part (docs/realtime.md, *Repeatable runs*).

:func:`every` runs the callback from the clock itself instead: a jump callback on the node's
sim clock, called when the node takes a ``/clock`` message, in the executor's own order (like
the lockstep answer of :mod:`scara_collab.nodes.lockstep`, and before it, when created first:
the node answers sim time once the tick's work is done). It fires like a timer: when sim time
reaches the next call, once however far time jumped, the next call ``period`` later on the
same grid. On wall time it is an ordinary timer.
"""
from typing import Callable

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node

from scara_collab.nodes.guarded import guarded


class SimTimer:
    """Call ``callback()`` every ``period`` sim seconds of ``node``'s clock; see the module."""

    def __init__(self, node: Node, period: float, callback: Callable[[], None]):
        """Start counting from the node's sim time now (0 before the first ``/clock``)."""
        if not period > 0:
            raise ValueError(f'timer period must be > 0 s, got {period}')
        self.period_ns = int(round(period * 1e9))
        self.callback = guarded(node, callback)
        self._clock = node.get_clock()
        self.next_ns = self._clock.now().nanoseconds + self.period_ns
        self.calls = 0
        self._handle = self._clock.create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None,
                          on_clock_change=False), post_callback=self._on_advance)
        # the node keeps it, as rclpy keeps a node's timers: the clock holds no reference to
        # its jump callbacks, so one collected while registered would be called after death
        if not hasattr(node, 'sim_timers'):
            node.sim_timers = []
        node.sim_timers.append(self)

    def _on_advance(self, _jump) -> None:
        now = self._clock.now().nanoseconds
        if now < self.next_ns:
            return
        behind = (now - self.next_ns) // self.period_ns
        self.next_ns += (behind + 1) * self.period_ns
        self.calls += 1
        self.callback()


def every(node: Node, period: float, callback: Callable[[], None]):
    """Run ``callback`` every ``period`` s of the node's time; return the timer.

    On sim time (``use_sim_time``) a :class:`SimTimer`, else ``node.create_timer``. The
    callback is guarded (:func:`scara_collab.nodes.guarded.guarded`) either way.
    """
    if node.get_parameter('use_sim_time').value:
        return SimTimer(node, period, callback)
    return node.create_timer(period, guarded(node, callback))
