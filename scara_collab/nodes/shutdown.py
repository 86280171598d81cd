"""What a node says before its rclpy context goes down: the context's pre-shutdown hooks.

rclpy's ``Context.on_shutdown`` calls its callbacks after rcl has shut the context down, when
no publisher of it can publish any more; a goodbye (a lockstep participant's leave) must go out
before. :func:`before_shutdown` keeps such callbacks per context, as rclcpp's
``add_pre_shutdown_callback`` does, and :func:`close` runs them, then destroys the nodes and
shuts the context down. A context shut down some other way (a signal handler, a test's
``try_shutdown``) forgets its callbacks through ``Context.on_shutdown``, uncalled.

>>> import rclpy
>>> ctx = rclpy.Context()
>>> said = []
>>> before_shutdown(ctx, lambda: said.append('bye'))
>>> close(ctx, [])
>>> said
['bye']
"""
from typing import Callable, Dict, Iterable, List, Optional
import weakref

import rclpy
from rclpy.context import Context
from rclpy.node import Node

_HOOKS: 'weakref.WeakKeyDictionary[Context, List[Callable[[], None]]]' = (
    weakref.WeakKeyDictionary())


def before_shutdown(context: Context, callback: Callable[[], None]) -> None:
    """Call ``callback()`` when :func:`close` closes ``context``, before anything is destroyed.

    :param context: the context the caller's node lives in.
    :param callback: takes no argument; an exception in it is ignored (best effort).
    """
    hooks = _HOOKS.get(context)
    if hooks is None:
        hooks = _HOOKS[context] = []
        context.on_shutdown(_forget(context))
    hooks.append(callback)


def _forget(context: Context) -> Callable[[], None]:
    ref = weakref.ref(context)

    def forget() -> None:
        ctx = ref()
        if ctx is not None:
            _HOOKS.pop(ctx, None)
    return forget


def run_hooks(context: Context) -> int:
    """Call (once) the callbacks registered for ``context``; return how many there were."""
    hooks: Dict = _HOOKS.pop(context, [])
    for callback in hooks:
        try:
            callback()
        except Exception:  # noqa: B902 - a goodbye is best effort
            pass
    return len(hooks)


def close(context: Optional[Context], nodes: Iterable[Node]) -> None:
    """Run ``context``'s pre-shutdown callbacks, destroy ``nodes``, shut ``context`` down.

    :param context: None: rclpy's default context, which is then replaced by a fresh one, so
        ``rclpy.init()`` works again in this process (as after ``rclpy.try_shutdown()``).
    """
    run_hooks(rclpy.get_default_context() if context is None else context)
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown(context=context)
