"""Run one node executable for the launcher: ``python -m scara_collab.run.child MODULE:FUNC ...``.

The same entry points as the console scripts (``scara_collab.nodes.planner:main_left``, ...),
started with the launcher's interpreter, so it works in a venv and in a colcon install alike.
The remaining arguments (``--ros-args ...``) reach ``rclpy.init`` through ``sys.argv``.

On Linux the child asks to be sent SIGTERM when the launcher dies (``PR_SET_PDEATHSIG``), so
a launcher killed with SIGKILL does not leave an unthrottled simulator running. rclpy turns
SIGTERM, like SIGINT, into a clean shutdown of the node.
"""
import importlib
import os
import signal
import sys
from typing import List, Optional

_PR_SET_PDEATHSIG = 1


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
        sys.exit('usage: python -m scara_collab.run.child MODULE:FUNC [--ros-args ...]')
    die_with_parent(int(os.environ.get('SCARA_LAUNCHER_PID', os.getppid())))
    module, func = argv[1].split(':', 1)
    try:
        entry = getattr(importlib.import_module(module), func)
    except KeyboardInterrupt:  # stopped while importing, before rclpy handles signals
        sys.exit(128 + signal.SIGINT)
    sys.argv = [f'{module}:{func}'] + argv[2:]
    entry()


if __name__ == '__main__':
    main()
