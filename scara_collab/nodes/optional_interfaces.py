"""Interfaces without PyPI wheels (``control_msgs``, ``tf2_msgs``): present only where they load.

``scripts/build_interfaces`` builds them into the venv; a ROS install has them. A node that
uses one asks :func:`optional_interface` for its type at import time, runs without what needs
it where it is absent, and says so with :meth:`OptionalInterface.say_absent`. Present means
more than importable: the type support (the generated C extension and the package's libraries
on the library path) must load, as a publisher or an action server needs it. A package whose
Python modules import but whose libraries are not found (a process started with another
environment's library path) is absent too, with a warning that names it and the reason,
instead of ending the node where it creates the publisher or server.
"""
from dataclasses import dataclass
import importlib
import importlib.util
from typing import Optional

from rclpy.exceptions import NoTypeSupportImportedException
from rclpy.type_support import check_for_type_support
from rosidl_generator_py.import_type_support_impl import UnsupportedTypeSupport

#: what a type support that does not load raises
LOAD_ERRORS = (ImportError, OSError, AttributeError, UnsupportedTypeSupport,
               NoTypeSupportImportedException)


@dataclass(frozen=True)
class OptionalInterface:
    """An interface type that may be absent: ``type`` is ``None`` then, ``reason`` says why."""

    name: str                # 'control_msgs/action/FollowJointTrajectory'
    type: Optional[type]     # the message, service or action class where it loads
    reason: str = ''         # why it is absent
    installed: bool = False  # absent although its package imports: its type support fails

    def say_absent(self, logger, without: str) -> None:
        """Say on ``logger`` that the node runs ``without`` what needs it, if it is absent.

        A warning if the package is installed but does not load, else a note.
        """
        if self.type is not None:
            return
        text = f'{self.name}: {self.reason}; {without}'
        if self.installed:
            logger.warning(text)
        else:
            logger.info(text)


def _cause(exc: BaseException) -> str:
    """Return the innermost message of ``exc`` (rosidl hides the library that was not found)."""
    while exc.__cause__ or exc.__context__:
        exc = exc.__cause__ or exc.__context__
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def optional_interface(module: str, name: str) -> OptionalInterface:
    """Return the type ``name`` of ``module`` (``'control_msgs.action'``) if its support loads.

    >>> optional_interface('std_msgs.msg', 'String').type.__name__
    'String'
    >>> optional_interface('no_such_msgs.msg', 'Nothing').reason
    'no_such_msgs is not installed (./scripts/build_interfaces builds it)'
    """
    package, kind = module.split('.')[0], module.split('.')[-1]
    full = f'{package}/{kind}/{name}'
    try:
        cls = getattr(importlib.import_module(module), name)
    except ImportError as exc:
        if importlib.util.find_spec(package) is None:
            return OptionalInterface(full, None, f'{package} is not installed '
                                     '(./scripts/build_interfaces builds it)')
        return OptionalInterface(full, None, f'{package} is installed but does not import '
                                 f'({_cause(exc)})', installed=True)
    try:
        check_for_type_support(cls)
    except LOAD_ERRORS as exc:
        return OptionalInterface(full, None, f'{package} is installed but its type support '
                                 f'does not load ({_cause(exc)})', installed=True)
    return OptionalInterface(full, cls)
