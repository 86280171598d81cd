"""Several nodes of the cell in one process, on one executor (``launch_cell.py --one-process``).

``python -m scara_collab.run.container [--fault SPEC ...] --node MODULE:FUNC [--ros-args ...]
--node ...``

Each ``--node`` names a node by the entry point of its executable (the launcher's stages:
``scara_collab.nodes.planner:main_left``, ...) followed by that node's own ``--ros-args``,
which become its ``cli_args`` (parameters and parameter files apply to it alone). All nodes
are built in the order given and spin on one executor (:func:`scara_collab.nodes.runner.
run_nodes`): the ROS 2 way to run a graph in one process, as a component container does. The
messages between them still go through DDS, but no callback waits for another process to be
scheduled, and the process pays one executor and one interpreter instead of six.

Like :mod:`scara_collab.run.child`, the container asks for SIGTERM when the launcher dies,
and leading ``--fault SPEC`` pairs (the launcher's ``--fault``) build every node with the fault
injection's hook (:func:`scara_collab.run.faults.hook`), each with its own fault plan.
"""
import functools
import os
import signal
import sys
from typing import Callable, List, Optional, Sequence, Tuple

from rclpy.node import Node

from scara_collab import graph
from scara_collab.nodes.runner import run_nodes
from scara_collab.run.child import die_with_parent, take_faults

FLAG = '--node'


def parse(argv: Sequence[str]) -> List[Tuple[str, List[str]]]:
    """Split ``--node ENTRY args... --node ENTRY args...`` into ``[(entry, args), ...]``.

    :raises ValueError: no node, an argument before the first ``--node``, or an entry point
        that is not a node of :mod:`scara_collab.graph`.
    """
    out: List[Tuple[str, List[str]]] = []
    it = iter(argv)
    for token in it:
        if token == FLAG:
            entry = next(it, None)
            if entry is None:
                raise ValueError(f'{FLAG} needs an entry point')
            if entry not in graph.BY_ENTRY:
                raise ValueError(f'unknown node {entry!r}; one of: {", ".join(graph.BY_ENTRY)}')
            out.append((entry, []))
        elif not out:
            raise ValueError(f'expected {FLAG} ENTRY first, got {token!r}')
        else:
            out[-1][1].append(token)
    if not out:
        raise ValueError(f'no node given ({FLAG} ENTRY [--ros-args ...], repeated)')
    return out


def factory(entry: str, args: Sequence[str],
            wrap: Optional[Callable[[type], type]] = None) -> Callable[[], Node]:
    """Return a callable that builds the node of ``entry`` with its own ``cli_args``.

    :param wrap: the fault injection's hook (:meth:`scara_collab.graph.NodeSpec.build`).
    """
    return functools.partial(graph.BY_ENTRY[entry].build, wrap=wrap, cli_args=list(args))


def main(argv: Optional[List[str]] = None) -> None:
    """Build the nodes named on the command line and spin them on one executor."""
    faults, argv = take_faults(sys.argv[1:] if argv is None else argv)
    try:
        nodes = parse(argv)
    except ValueError as exc:
        sys.exit(f'usage: python -m scara_collab.run.container [--fault SPEC ...] {FLAG} '
                 f'MODULE:FUNC [--ros-args ...] ...: {exc}')
    die_with_parent(int(os.environ.get('SCARA_LAUNCHER_PID', os.getppid())))
    try:
        wrap = None
        if faults:
            from scara_collab.run.faults import hook
            wrap = hook(faults)
        factories = [factory(entry, args, wrap) for entry, args in nodes]
    except KeyboardInterrupt:  # stopped while importing, before rclpy handles signals
        sys.exit(128 + signal.SIGINT)
    run_nodes(factories, args=[])


if __name__ == '__main__':
    main()
