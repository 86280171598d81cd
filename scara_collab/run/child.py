"""Run one node executable for the launcher: ``python -m scara_collab.run.child MODULE:FUNC ...``.

The same entry points as the console scripts (``scara_collab.nodes.planner:main_left``, ...),
started with the launcher's interpreter, so it works in a venv and in a colcon install alike.
The remaining arguments (``--ros-args ...``) reach ``rclpy.init`` through ``sys.argv``.

``--fault SPEC`` pairs right after the entry (the launcher's ``--fault``) build the node of
that entry (:data:`scara_collab.graph.BY_ENTRY`) with the fault injection's hook
(:func:`scara_collab.run.faults.hook`) and spin it as the entry point would; without them the
entry point runs as it is, and the fault injection is not imported.

On Linux the child asks to be sent SIGTERM when the launcher dies (``PR_SET_PDEATHSIG``), so
a launcher killed with SIGKILL does not leave an unthrottled simulator running. rclpy turns
SIGTERM, like SIGINT, into a clean shutdown of the node.
"""
import functools
import importlib
import os
import signal
import sys
from typing import List, Optional, Sequence, Tuple

_PR_SET_PDEATHSIG = 1
FAULT = '--fault'


def take_faults(argv: Sequence[str]) -> Tuple[List[str], List[str]]:
    """Return the leading ``--fault SPEC`` pairs' specs and the arguments after them.

    >>> take_faults(['--fault', 'drop:/a:1', '--ros-args', '-p', 'x:=1'])
    (['drop:/a:1'], ['--ros-args', '-p', 'x:=1'])
    """
    argv, faults = list(argv), []
    while len(argv) >= 2 and argv[0] == FAULT:
        faults.append(argv[1])
        argv = argv[2:]
    return faults, argv


def die_with_parent(parent: int) -> None:
    """Ask Linux to send this process SIGTERM when ``parent`` dies (elsewhere: nothing).

    :param parent: the launcher's pid; if it is gone already, SIGTERM is sent at once.
    """
    if not sys.platform.startswith('linux'):
        return
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the launcher died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


def main(argv: Optional[List[str]] = None) -> None:
    """Import ``MODULE:FUNC`` from the first argument and call it with the rest in argv."""
    argv = list(sys.argv if argv is None else argv)
    if len(argv) < 2 or ':' not in argv[1]:
        sys.exit('usage: python -m scara_collab.run.child MODULE:FUNC [--fault SPEC ...] '
                 '[--ros-args ...]')
    die_with_parent(int(os.environ.get('SCARA_LAUNCHER_PID', os.getppid())))
    module, func = argv[1].split(':', 1)
    faults, rest = take_faults(argv[2:])
    try:
        entry = getattr(importlib.import_module(module), func)
        if faults:
            from scara_collab import graph
            from scara_collab.nodes.runner import run_node
            from scara_collab.run.faults import hook
            build = functools.partial(graph.BY_ENTRY[argv[1]].build, wrap=hook(faults))
    except KeyboardInterrupt:  # stopped while importing, before rclpy handles signals
        sys.exit(128 + signal.SIGINT)
    sys.argv = [f'{module}:{func}'] + rest
    if faults:
        run_node(build)  # as the entry point does, the node built with the hook
    else:
        entry()


if __name__ == '__main__':
    main()
