"""No exception escapes a callback: :func:`guarded` wraps one so that the node logs and lives on.

Every subscription, timer and service callback of the cell's nodes goes through it (SPEC §4: a
node never dies on a message).
"""
import functools
import traceback
from typing import Callable

from rclpy.node import Node


def guarded(node: Node, callback: Callable, service: bool = False) -> Callable:
    """Wrap a callback so that no exception escapes it: the node logs and lives on.

    A message the protocol or the conversions refuse (a ``ValueError``: malformed,
    non-finite, unknown names) is logged as a throttled warning with its reason; anything else
    is a bug, logged as an error with its traceback (throttled). A service callback answers
    ``success = False`` with the reason instead of leaving its client without a response.

    :param node: the node whose logger reports.
    :param callback: the subscription, timer or service callback.
    :param service: ``callback(request, response)`` is a service callback.
    """
    name = getattr(callback, '__name__', 'callback')

    @functools.wraps(callback)
    def run(*args):
        try:
            return callback(*args)
        except ValueError as exc:
            node.get_logger().warning(f'{name}: refused: {exc}', throttle_duration_sec=5.0)
            reason = f'refused: {exc}'
        except Exception as exc:  # noqa: B902 - the last-resort guard keeps the node alive
            node.get_logger().error(f'{name}: {type(exc).__name__}: {exc}\n'
                                    f'{traceback.format_exc()}', throttle_duration_sec=5.0)
            reason = f'internal error: {type(exc).__name__}: {exc}'
        if service and len(args) == 2:
            res = args[1]
            if hasattr(res, 'success'):
                res.success = False
            if hasattr(res, 'message'):
                res.message = reason
            return res
        return None
    return run
