"""In-process ROS test harness: one Context per test, nodes in one executor, waits with timeouts.

Not a test module itself (no ``test_`` prefix): the node tests import it.
"""
from pathlib import Path
import time
from typing import Callable, List

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from scara_collab import graph
from scara_collab.graph import ros_args

CONFIG = Path(__file__).resolve().parents[1] / 'config'


def params_args(*names: str, overrides: dict = None, namespace: str = '') -> List[str]:
    """``--ros-args`` loading the real ``config/<name>.yaml`` files, plus ``-p`` overrides.

    In a ``namespace``, also the cell's namespace and remaps (:func:`scara_collab.graph.ros_args`).
    """
    return ros_args(names, overrides, config_dir=CONFIG, namespace=namespace)


class Graph:
    """A Context, an executor and the nodes added to it; closed by :meth:`close`.

    :param namespace: the cell's namespace: the probe and the graph's nodes live there, so
        relative names (``collect(JointState, 'joint_states')``) are the cell's.
    """

    def __init__(self, namespace: str = ''):
        """Initialise a Context of its own, with an executor and the ``probe`` node."""
        self.namespace = graph.namespace_of(namespace)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: List[Node] = []
        self.probe = self.add(Node('probe', context=self.context,
                                   cli_args=graph.node_args(self.namespace)))

    def add(self, node: Node) -> Node:
        """Add ``node`` to the executor and return it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def add_node_of(self, name: str, **overrides) -> Node:
        """Build the graph's node ``name`` (:mod:`scara_collab.graph`) with its configs, add it.

        ``overrides`` are its ``-p`` parameters, set after the config files.
        """
        spec = graph.node(name)
        return self.add(spec.build(context=self.context,
                                   cli_args=params_args(*spec.configs, overrides=overrides,
                                                        namespace=self.namespace)))

    def spin_until(self, predicate: Callable[[], bool], timeout: float = 20.0) -> bool:
        """Spin until ``predicate()`` is true; False if ``timeout`` wall seconds pass first."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.005)
        return predicate()

    def collect(self, msg_type, topic: str, qos=10) -> list:
        """Subscribe the probe to ``topic``; returns the list the messages are appended to."""
        out: list = []
        self.probe.create_subscription(msg_type, topic, out.append, qos)
        return out

    def call(self, srv_type, name: str, request, timeout: float = 20.0):
        """Call a service from the probe and spin until the answer (or fail)."""
        client = self.probe.create_client(srv_type, name)
        assert self.spin_until(client.service_is_ready, timeout), f'{name} not available'
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout), f'{name} did not answer'
        return future.result()

    def close(self) -> None:
        """Shut down the executor, destroy every node and shut down the Context."""
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)
