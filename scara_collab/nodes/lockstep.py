"""Lockstep between the simulator and the nodes that act on sim time.

Gazebo with ros2_control can run its controllers in lockstep with physics; a graph of
separate processes cannot, unless the clock waits for them. Without it, a node that computes
(a planner planning, the automation manager computing an intercept) sees its sim clock stand
still while the bridge steps on: its plans start late and moving items are missed, more so the
faster the simulation runs or the busier the CPU.

The protocol, on one topic ``sim/lockstep`` (``std_msgs/Header``, relative: each cell's
namespace has its own lockstep):

* a *participant* answers every advance of its node's sim clock (a clock jump callback, run
  when the node's time source takes a clock message, so no second subscription) with a
  Header whose ``frame_id`` is its node's full name (``/cell_1/left_planner`` in a cell's
  namespace) and ``stamp`` the sim time it has
  reached; it answers only between callbacks, so while it computes it does not answer;
* the bridge (:class:`LockstepGate`) never steps more than ``window`` sim seconds beyond the
  oldest answer of the participants it has heard. A busy node therefore holds sim time
  (within ``window``) until it is done, as if the whole graph ran in one thread;
* a participant may hold its answer until another node has replied to what it sent (the
  automation manager, until a planner's status for the move it offered and the bridge's
  answer to a gripper call; a planner, until the bridge's status of each move it sent:
  :meth:`LockstepParticipant.await_reply`), at most ``REPLY_WAIT``
  wall seconds: sim time then waits for the reply too, and the next ``/clock`` finds it
  taken, however the processes were scheduled (docs/realtime.md, *Repeatable runs*). A reply
  delayed on sim time (a ``delay:`` or ``latency:`` fault) cannot come while sim time waits for it:
  it costs ``REPLY_WAIT`` wall seconds, and the run is no longer repeatable;
* a participant that leaves says so (stamp = the end of time), before its context shuts
  down (:func:`scara_collab.nodes.shutdown.before_shutdown`); one that keeps the bridge
  waiting for ``timeout`` wall seconds is dropped with a warning, and joins again with its
  next answer. The simulation never hangs on a dead node. The wait is counted per
  participant, from when its answer began to hold sim time back (or its last answer, if
  later), never from the age of its last answer alone: while sim time stands still nobody
  gets a new ``/clock`` to answer, so the others' answers age too, and one frozen node must
  not take them all down. ``timeouts`` overrides ``timeout`` for named nodes;
* the bridge may *expect* participants (``lockstep_expect``: the launcher and the in-process
  job name the nodes they start): it waits for them from the start, as if they had answered
  sim time 0, so the first steps do not depend on how soon each node answers;
* unthrottled, the bridge steps to its limit at once and the answer that moves the limit
  steps it on, in that answer's callback: in one process every step takes its turn in the
  executor's order, and the same seed gives the same run (docs/realtime.md, *Repeatable runs*);
* a *guard* (the collision monitor) is a participant without which the arms must not move:
  before the gate drops a guard, or when a guard leaves, it tells the bridge (``on_guard``),
  which holds both arms and refuses trajectories until the guard answers again
  (:attr:`LockstepGate.absent`). Without a window (``lockstep_window`` 0: real time, the
  clock waits for nobody) the gate still hears the guards: a guard whose newest answer is
  more than its timeout behind sim time (sim s: the time the arms moved unwatched; a paused
  bridge does not count) holds the arms the same way, until an answer brings it back within
  its timeout. The other participants still answer (the launcher's liveness watch reads
  them); the bridge just does not wait for them.

Nodes join with :func:`join` (parameter ``lockstep``, default true; only on sim time), which
returns their :class:`LockstepParticipant`. The bridge's parameters ``lockstep_window`` (sim
s, 0 = off), ``lockstep_timeout`` (wall s), ``lockstep_timeouts`` (``['node:seconds', ...]``,
:func:`parse_timeouts`), ``lockstep_guards`` (node names, default ``['collision_monitor']``)
and ``lockstep_expect`` (node names) configure the gate; a relative node name there is a node
of the bridge's own namespace (:func:`full_name`).
Messages are the standard ``std_msgs/Header``, so ``ros2 topic echo /sim/lockstep`` shows who
is answering.
"""
import time
from typing import Callable, Dict, Iterable, Optional

from builtin_interfaces.msg import Time
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Header

from scara_collab import graph
from scara_collab.nodes import shutdown
from scara_collab.nodes.guarded import guarded

TOPIC = 'sim/lockstep'  # relative: in the cell's namespace
#: transient local: an answer published before the bridge's subscription has matched the
#: participant's new publisher (a node started last, on a busy machine) is delivered when it
#: matches, instead of lost: a lost answer holds sim time until the lockstep timeout
QOS = QoSProfile(depth=50, durability=DurabilityPolicy.TRANSIENT_LOCAL)
END_OF_TIME = Time(sec=2**31 - 1, nanosec=0)
#: wall s a participant holds its answer for an awaited reply (a lost one: then it answers).
#: Until then a slow reply looks the same, and one answered without it makes the run depend
#: on scheduling: with 30 processes on 2 cores a plan of 20-50 ms CPU can take over 0.5 s
#: wall. 2 s covers that, within the bridge's 5 s ``lockstep_timeout`` for the waiting node
REPLY_WAIT = 2.0


def _sec(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def full_name(name: str, namespace: str = '') -> str:
    """Return a node name as the participants sign their answers (the node's full name).

    A relative name is a node of ``namespace``; an absolute one stays as it is.

    >>> full_name('monitor'), full_name('monitor', '/cell_1'), full_name('/monitor', '/cell_1')
    ('/monitor', '/cell_1/monitor', '/monitor')
    """
    return graph.resolve(name.strip(), namespace)


def parse_timeouts(entries: Iterable[str], namespace: str = '') -> Dict[str, float]:
    """Parse per-node timeouts: ``['collision_monitor:2.0']`` -> ``{'/collision_monitor': 2.0}``.

    Empty entries are ignored (a string-array parameter cannot be empty).

    :param entries: ``'<node>:<wall seconds>'`` strings; a relative node name is one of
        ``namespace`` (:func:`full_name`).
    :param namespace: the namespace of relative node names (the bridge's).
    :raises ValueError: an entry without a name, or a timeout that is not a number > 0.
    """
    out: Dict[str, float] = {}
    for entry in entries:
        if not entry.strip():
            continue
        name, _, value = entry.rpartition(':')
        try:
            seconds = float(value)
        except ValueError:
            seconds = float('nan')
        if not name.strip() or not seconds > 0:
            raise ValueError(f'lockstep timeout {entry!r}: expected <node>:<seconds > 0>, '
                             "e.g. 'collision_monitor:2.0'")
        out[full_name(name, namespace)] = seconds
    return out


class LockstepParticipant:
    """Answer the clock on ``sim/lockstep`` for ``node``; see the module docstring.

    It leaves the lockstep before ``node``'s context shuts down
    (:func:`scara_collab.nodes.shutdown.before_shutdown`), or when :meth:`leave` is called.
    """

    def __init__(self, node: Node):
        """Answer every forward step of ``node``'s sim clock on ``sim/lockstep``."""
        self.node = node
        self.name = node.get_fully_qualified_name()
        self._pub = node.create_publisher(Header, TOPIC, QOS)
        self._clock = node.get_clock()
        # every forward step of sim time (the time source keeps only the newest /clock)
        self._handle = self._clock.create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None,
                          on_clock_change=False), post_callback=self._on_advance)
        self.answered = 0
        self.awaited: Dict[object, float] = {}  # reply key -> wall deadline
        self.owed = False  # an answer held back for a reply
        self.late = 0  # replies given up on (their wall deadline passed)
        self.left = False
        self._timer = None
        shutdown.before_shutdown(node.context, self.leave)

    def _on_advance(self, _jump) -> None:
        if self.awaited:
            self.owed = True
            return
        self._answer()

    def _answer(self) -> None:
        self.owed = False
        self._pub.publish(Header(stamp=self._clock.now().to_msg(), frame_id=self.name))
        self.answered += 1

    def await_reply(self, key, seconds: float = REPLY_WAIT) -> None:
        """Hold this node's answers until :meth:`reply` ``(key)``, at most ``seconds`` (wall)."""
        self.awaited[key] = time.monotonic() + seconds
        if self._timer is None:  # the deadline is wall time: sim time waits for this node
            self._timer = self.node.create_timer(
                0.05, guarded(self.node, self._expire),
                clock=Clock(clock_type=ClockType.STEADY_TIME))

    def reply(self, key) -> None:
        """Take the reply ``key`` (others are ignored); answer when none is awaited any more."""
        if self.awaited.pop(key, None) is not None and not self.awaited and self.owed:
            self._answer()

    def _expire(self) -> None:
        now = time.monotonic()
        lost = [k for k, deadline in self.awaited.items() if deadline <= now]
        for key in lost:
            del self.awaited[key]
        if lost:
            self.late += len(lost)
            self.node.get_logger().warning(
                f'lockstep: no reply to {lost} by its deadline (wall); answering without '
                'it', throttle_duration_sec=5.0)
            if self.owed and not self.awaited:
                self._answer()

    def leave(self) -> None:
        """Tell the bridge not to wait for this node any more (once; best effort)."""
        if self.left:
            return
        self.left = True
        try:
            self._pub.publish(Header(stamp=END_OF_TIME, frame_id=self.name))
        except Exception:  # noqa: B902 - the node or its context may already be gone
            pass


def join(node: Node) -> Optional[LockstepParticipant]:
    """Make ``node`` a lockstep participant unless its parameter ``lockstep`` is false.

    Declares ``lockstep`` (bool, default true). Nodes on wall time do not take part.

    :return: the participant (the node keeps it if it awaits replies), or None.
    """
    if not node.has_parameter('lockstep'):
        node.declare_parameter('lockstep', True)
    if not node.get_parameter('lockstep').value:
        return None
    if not node.get_parameter('use_sim_time').value:
        return None
    return LockstepParticipant(node)


class LockstepGate:
    """The bridge's side: how far physics may step, given the participants' answers.

    :param node: the bridge node (subscribes ``sim/lockstep``; its namespace is the one of
        the relative names in ``timeouts``, ``guards`` and ``expect``).
    :param window: sim seconds the bridge may run ahead of the oldest answer; 0 = no gate.
    :param timeout: wall seconds a participant may keep the bridge waiting before it is
        dropped (it joins again when it answers).
    :param on_answer: called after each answer (the bridge re-arms its stepping timer).
    :param timeouts: per-node ``timeout`` (full node names, see :func:`parse_timeouts`).
    :param guards: names of the participants the arms must not move without.
    :param on_guard: ``on_guard(name, present, why)``: a guard is about to be dropped or has
        left (``present`` false: hold the arms), or answers again (true). Called before the
        gate lets sim time go on without the guard.
    :param wall_clock: wall time source, s (tests pass a fake one).
    :param expect: names of participants waited for from the start, as if they had
        answered sim time 0 (dropped after their timeout like any other).

    With ``window`` 0 the gate waits for nobody (:meth:`limit` is ``inf``) but still watches
    the ``guards`` (see the module docstring): their timeouts then count sim seconds behind.
    """

    def __init__(self, node: Node, window: float, timeout: float,
                 on_answer: Optional[Callable[[], None]] = None,
                 timeouts: Optional[Dict[str, float]] = None, guards: Iterable[str] = (),
                 on_guard: Optional[Callable[[str, bool, str], None]] = None,
                 wall_clock: Callable[[], float] = time.monotonic,
                 expect: Iterable[str] = ()):
        """Store the settings; with a window or guards, subscribe ``sim/lockstep``."""
        self.node = node
        self.window = float(window)
        self.timeout = float(timeout)
        self.timeouts = dict(timeouts or {})
        ns = node.get_namespace()
        self.guards = frozenset(full_name(g, ns) for g in guards)
        self.on_answer = on_answer
        self.on_guard = on_guard
        self._wall = wall_clock
        self.reached: Dict[str, float] = {}     # participant -> sim time it has reached
        self.dropped: Dict[str, float] = {}     # participant -> sim time when dropped
        self.waited: Dict[str, float] = {}      # participant -> wall s the bridge waited
        self.since: Dict[str, float] = {}       # participant holding sim time -> wall since
        self.absent: Dict[str, str] = {}        # guard -> why it is missing (arms held)
        self.sim_now = 0.0                      # the sim time of the last look (limit)
        if self.window > 0:
            self.reached.update({full_name(n, ns): 0.0 for n in expect})
            if self.reached:
                node.get_logger().info(f'lockstep: waiting from the start for '
                                       f'{", ".join(sorted(self.reached))}')
        elif self.guards:  # real time: wait for nobody, but never move the arms unwatched
            self.reached.update({n: 0.0 for n in (full_name(e, ns) for e in expect)
                                 if n in self.guards})
            node.get_logger().info(
                f'lockstep off: waiting for nobody; watching {", ".join(sorted(self.guards))} '
                '(the arms hold when one is more than its timeout, sim s, behind)')
        if self.window > 0 or self.guards:
            node.create_subscription(Header, TOPIC, guarded(node, self.receive), QOS)

    @property
    def enabled(self) -> bool:
        """Return True if the gate holds physics back (``window > 0``)."""
        return self.window > 0

    def timeout_of(self, name: str) -> float:
        """Return the wall seconds ``name`` may keep the bridge waiting."""
        return self.timeouts.get(name, self.timeout)

    def receive(self, msg: Header) -> None:
        """Take one answer from ``sim/lockstep`` (the subscription's callback)."""
        name, t = msg.frame_id, _sec(msg.stamp)
        if not self.enabled:
            self._watch_answer(name, msg)
            return
        log = self.node.get_logger()
        self._stop_waiting(name)
        if msg.stamp.sec == END_OF_TIME.sec:
            if self.reached.pop(name, None) is not None:
                log.info(f'lockstep: {name} left')
                if name in self.guards:
                    self._guard_missing(name, 'left the lockstep')
            self.dropped.pop(name, None)
        else:
            if name not in self.reached:
                again = ' again' if self.dropped.pop(name, None) is not None else ''
                log.info(f'lockstep: {name} joined{again} (window {self.window:.3f} s)')
            self.reached[name] = max(t, self.reached.get(name, t))
            if self.absent.pop(name, None) is not None and self.on_guard is not None:
                self.on_guard(name, True, 'answers again')
        if self.on_answer is not None:
            self.on_answer()

    def limit(self, sim_now: float) -> float:
        """Return the sim time physics may step to now (``inf`` when nobody is waited for).

        Also drops each participant that has held sim time back for its timeout (wall s,
        counted from when it began to hold it back); a guard's ``on_guard`` comes first.
        """
        self.sim_now = sim_now
        if not self.enabled:
            self._watch_guards(sim_now)
            return float('inf')
        if not self.reached:
            self._stop_waiting()
            return float('inf')
        wall = self._wall()
        holding = [n for n, t in self.reached.items() if t + self.window <= sim_now + 1e-9]
        for name in [n for n in self.since if n not in holding]:
            self._stop_waiting(name, wall)
        for name in holding:
            waited = wall - self.since.setdefault(name, wall)
            if waited > self.timeout_of(name):
                self._drop(name, sim_now, waited)
        if not self.reached:
            return float('inf')
        return min(self.reached.values()) + self.window

    def _watch_answer(self, name: str, msg: Header) -> None:
        """Without a window: take a guard's answer (the others are not waited for)."""
        if name not in self.guards:
            return
        if msg.stamp.sec == END_OF_TIME.sec:
            if self.reached.pop(name, None) is not None:
                self.node.get_logger().info(f'lockstep: {name} left')
                self._guard_missing(name, 'left the lockstep')
            return
        t = max(_sec(msg.stamp), self.reached.get(name, 0.0))
        self.reached[name] = t
        if name in self.absent and self.sim_now - t <= self.timeout_of(name):
            del self.absent[name]
            if self.on_guard is not None:
                self.on_guard(name, True, 'answers again')

    def _watch_guards(self, sim_now: float) -> None:
        """Without a window: hold the arms for a guard too far behind sim time."""
        for name, t in self.reached.items():
            behind = sim_now - t
            if name not in self.absent and behind > self.timeout_of(name):
                self._guard_missing(name, f'silent for {behind:.1f} s (sim) while sim time '
                                    'went on without it (lockstep off)')

    def _drop(self, name: str, sim_now: float, waited: float) -> None:
        why = f'silent for {waited:.1f} s (wall) while sim time waited for it'
        if name in self.guards:
            self._guard_missing(name, why)
        self.node.get_logger().warning(
            f'lockstep: {name} kept sim time waiting {waited:.1f} s (wall, timeout '
            f'{self.timeout_of(name):g} s); not waiting for it any more (it joins again when '
            'it answers)')
        self._stop_waiting(name)
        del self.reached[name]
        self.dropped[name] = sim_now

    def _guard_missing(self, name: str, why: str) -> None:
        if name not in self.absent:
            self.absent[name] = why
            if self.on_guard is not None:
                self.on_guard(name, False, why)

    def _stop_waiting(self, name: Optional[str] = None, wall: Optional[float] = None) -> None:
        for n in list(self.since) if name is None else [name]:
            since = self.since.pop(n, None)
            if since is not None:
                wall = self._wall() if wall is None else wall
                self.waited[n] = self.waited.get(n, 0.0) + wall - since

    def summary(self) -> str:
        """One line: who the bridge waited for, and how long (wall s)."""
        self._stop_waiting()
        if not self.waited:
            return 'lockstep: never waited'
        parts = sorted(self.waited.items(), key=lambda kv: -kv[1])
        return 'lockstep: waited ' + ', '.join(f'{n} {s:.2f} s' for n, s in parts)
