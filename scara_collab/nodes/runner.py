"""Run a node the way ros2/demos does on Jazzy: init, spin, clean shutdown on Ctrl-C."""
from typing import Callable, Optional

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from scara_collab.nodes import lockstep


def run_node(factory: Callable[[], Node], args: Optional[list] = None) -> None:
    """Create the node with ``factory()`` and spin it until Ctrl-C or an external shutdown.

    :param factory: builds the node (called after ``rclpy.init``).
    :param args: command-line arguments for ``rclpy.init`` (``--ros-args ...``).
    """
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            lockstep.leave(node)
            node.destroy_node()
        rclpy.try_shutdown()


def close_graph(executor, nodes, context) -> None:
    """Tear down nodes built in-process: stop the executor, destroy the nodes, shut down.

    :param executor: the executor the nodes were added to.
    :param nodes: the nodes, in any order.
    :param context: the ``rclpy.Context`` they were created in.
    """
    executor.shutdown()
    for node in nodes:
        lockstep.leave(node)
        node.destroy_node()
    rclpy.try_shutdown(context=context)
