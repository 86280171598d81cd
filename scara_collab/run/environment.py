"""The environment of the processes the launcher starts: its own Python environment's ROS.

The ROS 2 PyPI wheels set their process up at start-up: ``ros_wheels_bootstrapper.pth`` in
site-packages runs, unless the variable :data:`MARKER` is set, and starts the interpreter
again with :data:`LIBRARY_PATH` extended by the environment's ``lib/`` (the libraries of the
message packages, ``scripts/build_interfaces``' ``control_msgs`` and ``tf2_msgs`` among them)
and each wheel's ``ros_*.libs/``, and with :data:`MARKER` set. A child inherits both, so a
launcher started from a process set up by another environment's wheels (a test harness, a
notebook, a tool of its own) would pass on that environment's libraries, and its nodes would
skip their own set-up. :func:`node_environment` gives a child the launcher's own instead.
"""
import os
from pathlib import Path
import sys
from typing import Dict, List, Mapping, Optional

#: the variable the ROS wheels' start-up sets once it has extended the library path
MARKER = '_ROS_WHEELS_BOOTSTRAP_COMPLETE'
LIBRARY_PATH = 'LD_LIBRARY_PATH'
BOOTSTRAPPER = 'ros_wheels_bootstrapper.pth'  # in site-packages: the ROS wheels' start-up


def site_packages(prefix: Path) -> Path:
    """Return the site-packages of the Python environment at ``prefix``, as the wheels find it."""
    return prefix / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}' / (
        'site-packages')


def wheel_libraries(prefix: Path) -> List[str]:
    """Return the library folders the ROS wheels' start-up adds for ``prefix``, in a fixed order.

    Its ``lib/`` and each wheel's ``ros_*.libs/``; none if the environment has no ROS wheels.
    """
    site = site_packages(prefix)
    if not (site / BOOTSTRAPPER).is_file():
        return []
    return [str(prefix / 'lib')] + sorted(str(p.resolve()) for p in site.glob('ros_*.libs')
                                          if p.is_dir())


def environment_of(path: str) -> Optional[Path]:
    """Return the Python environment (a venv, or a ROS wheel's folder) ``path`` is part of.

    :return: the venv's folder (the one with ``pyvenv.cfg``), the ``ros_*.libs`` folder of a
        wheel installed outside a venv, else ``None``: a path of the system's or the user's.
    """
    p = Path(path).resolve()
    for folder in (p, *p.parents):
        if (folder / 'pyvenv.cfg').is_file():
            return folder
    return next((f for f in (p, *p.parents)
                 if f.name.startswith('ros_') and f.name.endswith('.libs')), None)


def node_environment(environ: Mapping[str, str],
                     prefix: Optional[Path] = None) -> Dict[str, str]:
    """Return ``environ`` for a node process of the Python environment at ``prefix``.

    The library path holds the environment's own ROS libraries first (:func:`wheel_libraries`),
    then the inherited folders that belong to no other Python environment; :data:`MARKER` is
    set where those are the wheels' own (the child need not start again), else removed.

    :param environ: the environment to start from (the launcher's ``os.environ``).
    :param prefix: the launcher's Python environment (default: ``sys.prefix``).
    """
    prefix = Path(sys.prefix if prefix is None else prefix).resolve()
    own = wheel_libraries(prefix)
    kept = []
    for folder in environ.get(LIBRARY_PATH, '').split(os.pathsep):
        if folder and folder not in own and folder not in kept and (
                environment_of(folder) in (None, prefix)):
            kept.append(folder)
    env = dict(environ)
    env.pop(MARKER, None)
    env.pop(LIBRARY_PATH, None)
    if own or kept:
        env[LIBRARY_PATH] = os.pathsep.join(own + kept)
    if own:
        env[MARKER] = '1'
    return env
