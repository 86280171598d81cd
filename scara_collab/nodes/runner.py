"""Run a node the way ros2/demos does on Jazzy: init, spin, clean shutdown on Ctrl-C.

Executables spin on rclpy's ``EventsExecutor`` (rclpy.experimental, in Jazzy since 7.1): it
dispatches callbacks from C++ and costs about a third of the CPU per message of the
``SingleThreadedExecutor`` (31 vs 105 µs per JointState here), which matters when every node
hears ``/clock`` (50 Hz) and ``/joint_states`` (100 Hz) in sim time, times the real-time
factor.
``SCARA_COLLAB_EXECUTOR=single`` selects the ``SingleThreadedExecutor`` instead.
"""
import os
import signal
from typing import Callable, List, Optional, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from scara_collab.nodes import shutdown


EXECUTORS = ('events', 'single')
DISCOVERY_ENV = 'ROS_AUTOMATIC_DISCOVERY_RANGE'


def localhost_by_default() -> None:
    """Keep DDS discovery on this host unless the user's environment says otherwise.

    Called before ``rclpy.init`` by every entry point (the executables, ``ros2 run``, the
    launcher), so a cell started on a shared network never talks to another one by accident.
    """
    os.environ.setdefault(DISCOVERY_ENV, 'LOCALHOST')


def make_executor(kind: Optional[str] = None, context=None) -> Executor:
    """Return the executor ``kind`` (default: ``$SCARA_COLLAB_EXECUTOR`` or ``events``)."""
    kind = kind or os.environ.get('SCARA_COLLAB_EXECUTOR', 'events')
    if kind not in EXECUTORS:
        raise ValueError(f'SCARA_COLLAB_EXECUTOR must be one of {EXECUTORS}, got {kind!r}')
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:  # an rclpy without it: fall back
            return SingleThreadedExecutor(context=context)
        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def _note_signals() -> list:
    """Return a list that becomes non-empty on SIGINT; the spin loop then ends cleanly.

    Python's own handler would raise ``KeyboardInterrupt`` wherever the interpreter is, most
    often inside a callback the executor called from C++, which logs that as a fatal callback
    exception on every Ctrl-C. A handler installed before this one (not Python's default) still
    runs.
    """
    seen: list = []
    previous = signal.getsignal(signal.SIGINT)

    def note(signum, frame):
        seen.append(signum)
        if callable(previous) and previous is not signal.default_int_handler:
            previous(signum, frame)
    signal.signal(signal.SIGINT, note)
    return seen


def companions(node: Node) -> List[Node]:
    """Return the nodes ``node`` built in its process, to be spun with it.

    The bridge's wired separation monitor (``node.companions``); the node destroys them with
    itself.
    """
    return list(getattr(node, 'companions', ()))


def run_node(factory: Callable[[], Node], args: Optional[list] = None) -> None:
    """Create the node with ``factory()`` and spin it until Ctrl-C or an external shutdown.

    :param factory: builds the node (called after ``rclpy.init``).
    :param args: command-line arguments for ``rclpy.init`` (``--ros-args ...``).
    """
    run_nodes([factory], args)


def run_nodes(factories: Sequence[Callable[[], Node]], args: Optional[list] = None) -> None:
    """Create several nodes and spin them all on one executor, in this process.

    The ROS 2 way to run nodes together (a component container): one executor serves every
    node's callbacks in turn, so no message waits for another process to be scheduled.

    :param factories: each builds one node (called after ``rclpy.init``, in order).
    :param args: command-line arguments for ``rclpy.init`` (``--ros-args ...``), global to
        every node; per-node arguments go to each node's ``cli_args``.
    """
    localhost_by_default()
    rclpy.init(args=args)
    nodes: List[Node] = []
    try:
        for factory in factories:
            nodes.append(factory())
        executor = make_executor()
        for node in nodes:
            for each in (node, *companions(node)):
                executor.add_node(each)
        # spin_once in a loop: the EventsExecutor's spin() ran no timers in our tests (7.1.6)
        stopping = _note_signals()
        while rclpy.ok() and not stopping:
            try:
                executor.spin_once(timeout_sec=0.25)
            except RuntimeError:
                # a signal while the EventsExecutor calls into Python (7.1.6) can come out as
                # "Unable to convert call argument"; after a SIGINT, the shutdown asked for
                if not stopping:
                    raise
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:  # the nodes' goodbyes (a lockstep leave) first: shutdown.before_shutdown
        shutdown.close(None, reversed(nodes))  # the default context


def close_graph(executor, nodes, context) -> None:
    """Tear down nodes built in-process: stop the executor, then :func:`shutdown.close`.

    :param executor: the executor the nodes were added to.
    :param nodes: the nodes, in any order.
    :param context: the ``rclpy.Context`` they were created in.
    """
    executor.shutdown()
    shutdown.close(context, nodes)


class InProcess:
    """Nodes built in this process on one executor, for benchmarks and tests that drive them.

    ``g = InProcess(); node = g.add(spec.build(context=g.context, ...)); g.spin_once(0.01)``
    and :meth:`close` (or a ``with`` block) at the end. Its own rclpy context, so several can
    live in one process one after another.

    :param executor: ``'events'`` or ``'single'`` (default: :func:`make_executor`'s).
    """

    def __init__(self, executor: Optional[str] = None):
        """Initialise a fresh context and its executor; no node yet."""
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = make_executor(executor, context=self.context)
        self.nodes: List[Node] = []

    def add(self, node: Node) -> Node:
        """Spin ``node`` (built in :attr:`context`) and its companions with the others.

        Return ``node``.
        """
        self.executor.add_node(node)
        for each in companions(node):
            self.executor.add_node(each)
        self.nodes.append(node)
        return node

    def probe(self, name: str) -> Node:
        """Add and return a plain node named ``name``, for the caller's own endpoints."""
        return self.add(Node(name, context=self.context))

    def spin_once(self, timeout_sec: float) -> None:
        """Run at most one callback, waiting up to ``timeout_sec`` for it."""
        self.executor.spin_once(timeout_sec=timeout_sec)

    def close(self) -> None:
        """Tear it all down (:func:`close_graph`)."""
        close_graph(self.executor, self.nodes, self.context)

    def __enter__(self) -> 'InProcess':
        """Return itself."""
        return self

    def __exit__(self, *exc) -> None:
        """Close it."""
        self.close()
