"""Lockstep between the simulator and the nodes that act on sim time.

Gazebo with ros2_control can run its controllers in lockstep with physics; a graph of
separate processes cannot, unless the clock waits for them. Without it, a node that computes
(a planner planning, the automation manager computing an intercept) sees its sim clock stand
still while the bridge steps on: its plans start late and moving items are missed, more so the
faster the simulation runs or the busier the CPU.

The protocol, on one topic ``/sim/lockstep`` (``std_msgs/Header``):

* a *participant* answers every advance of its node's sim clock (a clock jump callback, run
  when the node's time source takes a ``/clock`` message, so no second subscription) with a
  Header whose ``frame_id`` is its node's full name and ``stamp`` the sim time it has
  reached; it answers only between callbacks, so while it computes it does not answer;
* the bridge (:class:`LockstepGate`) never steps more than ``window`` sim seconds beyond the
  oldest answer of the participants it has heard. A busy node therefore holds sim time
  (within ``window``) until it is done, as if the whole graph ran in one thread;
* a participant that leaves says so (stamp = the end of time); one that stops answering for
  ``timeout`` wall seconds while the bridge waits for it is dropped with a warning, and joins
  again with its next answer. The simulation never hangs on a dead node.

Nodes join with :func:`join` (parameter ``lockstep``, default true; only on sim time). The
bridge's parameters ``lockstep_window`` (sim s, 0 = off) and ``lockstep_timeout`` (wall s)
configure the gate. Messages are the standard ``std_msgs/Header``, so ``ros2 topic echo
/sim/lockstep`` shows who is answering.
"""
import time
from typing import Callable, Dict, Optional

from builtin_interfaces.msg import Time
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Header

TOPIC = '/sim/lockstep'
QOS = QoSProfile(depth=50)
END_OF_TIME = Time(sec=2**31 - 1, nanosec=0)


def _sec(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class LockstepParticipant:
    """Answer ``/clock`` on ``/sim/lockstep`` for ``node``; see the module docstring."""

    def __init__(self, node: Node):
        self.node = node
        self.name = node.get_fully_qualified_name()
        self._pub = node.create_publisher(Header, TOPIC, QOS)
        self._clock = node.get_clock()
        # every forward step of sim time (the time source keeps only the newest /clock)
        self._handle = self._clock.create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None,
                          on_clock_change=False), post_callback=self._on_advance)
        self.answered = 0

    def _on_advance(self, _jump) -> None:
        self._pub.publish(Header(stamp=self._clock.now().to_msg(), frame_id=self.name))
        self.answered += 1

    def leave(self) -> None:
        """Tell the bridge not to wait for this node any more (best effort)."""
        try:
            self._pub.publish(Header(stamp=END_OF_TIME, frame_id=self.name))
        except Exception:  # noqa: B902 - the context may already be shut down
            pass


def join(node: Node) -> Optional[LockstepParticipant]:
    """Make ``node`` a lockstep participant unless its parameter ``lockstep`` is false.

    Declares ``lockstep`` (bool, default true). Nodes on wall time do not take part.
    """
    if not node.has_parameter('lockstep'):
        node.declare_parameter('lockstep', True)
    if not node.get_parameter('lockstep').value:
        return None
    if not node.get_parameter('use_sim_time').value:
        return None
    part = LockstepParticipant(node)
    node.lockstep = part
    return part


def leave(node: Node) -> None:
    """Announce that ``node`` leaves the lockstep, if it takes part."""
    part = getattr(node, 'lockstep', None)
    if isinstance(part, LockstepParticipant):
        part.leave()


class LockstepGate:
    """The bridge's side: how far physics may step, given the participants' answers.

    :param node: the bridge node (subscribes ``/sim/lockstep``).
    :param window: sim seconds the bridge may run ahead of the oldest answer; 0 = no gate.
    :param timeout: wall seconds a participant may keep the bridge waiting before it is
        dropped (it joins again when it answers).
    :param on_answer: called after each answer (the bridge re-arms its stepping timer).
    """

    def __init__(self, node: Node, window: float, timeout: float,
                 on_answer: Optional[Callable[[], None]] = None):
        self.node = node
        self.window = float(window)
        self.timeout = float(timeout)
        self.on_answer = on_answer
        self.reached: Dict[str, float] = {}     # participant -> sim time it has reached
        self.heard: Dict[str, float] = {}       # participant -> wall time of its last answer
        self.dropped: Dict[str, float] = {}     # participant -> sim time when dropped
        self.waited: Dict[str, float] = {}      # participant -> wall s the bridge waited
        self._blocked_since: Optional[float] = None
        self._blocker: Optional[str] = None
        if self.window > 0:
            node.create_subscription(Header, TOPIC, self._on_answer, QOS)

    @property
    def enabled(self) -> bool:
        return self.window > 0

    def _on_answer(self, msg: Header) -> None:
        name, t = msg.frame_id, _sec(msg.stamp)
        log = self.node.get_logger()
        if msg.stamp.sec == END_OF_TIME.sec:
            if self.reached.pop(name, None) is not None:
                log.info(f'lockstep: {name} left')
            self.heard.pop(name, None)
            self.dropped.pop(name, None)
        else:
            if name not in self.reached:
                again = ' again' if self.dropped.pop(name, None) is not None else ''
                log.info(f'lockstep: {name} joined{again} (window {self.window:.3f} s)')
            self.reached[name] = max(t, self.reached.get(name, t))
            self.heard[name] = time.monotonic()
        if self.on_answer is not None:
            self.on_answer()

    def limit(self, sim_now: float) -> float:
        """Return the sim time physics may step to now (``inf`` when nobody is waited for).

        Also drops a participant that has kept the bridge waiting for ``timeout`` wall s.
        """
        if not self.enabled or not self.reached:
            self._unblock()
            return float('inf')
        slowest = min(self.reached, key=self.reached.get)
        limit = self.reached[slowest] + self.window
        if limit > sim_now + 1e-9:
            self._unblock()
            return limit
        wall = time.monotonic()
        if self._blocked_since is None or self._blocker != slowest:
            self._unblock(wall)
            self._blocked_since, self._blocker = wall, slowest
        if wall - self.heard.get(slowest, wall) > self.timeout:
            self.node.get_logger().warning(
                f'lockstep: {slowest} has not answered for {self.timeout:.1f} s (wall); '
                f'not waiting for it any more (it joins again when it answers)')
            self._unblock(wall)
            del self.reached[slowest]
            self.heard.pop(slowest, None)
            self.dropped[slowest] = sim_now
            return self.limit(sim_now)
        return limit

    def _unblock(self, wall: Optional[float] = None) -> None:
        if self._blocked_since is not None:
            wall = time.monotonic() if wall is None else wall
            self.waited[self._blocker] = (self.waited.get(self._blocker, 0.0)
                                          + wall - self._blocked_since)
        self._blocked_since = self._blocker = None

    def summary(self) -> str:
        """One line: who the bridge waited for, and how long (wall s)."""
        self._unblock()
        if not self.waited:
            return 'lockstep: never waited'
        parts = sorted(self.waited.items(), key=lambda kv: -kv[1])
        return 'lockstep: waited ' + ', '.join(f'{n} {s:.2f} s' for n, s in parts)
