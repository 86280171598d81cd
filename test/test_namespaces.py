"""Two cells on one ROS domain, under /cell_0 and /cell_1: each sorts, neither hears the other.

Both graphs run in this process, each in its own context and executor (the nodes of
:mod:`scara_collab.graph` built with the cell's namespace and remaps, as the launcher starts
them), with a run recorder of its own in the cell's namespace. First only ``/cell_0`` is spun:
its lockstep must not wait for ``/cell_1``'s nodes, which do not answer. Then both run until
each has sorted an item.
"""
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_harness import Graph

from scara_collab import graph
from scara_collab.nodes import lockstep
from scara_collab.nodes.recorder import RunRecorder

CELLS = ('/cell_0', '/cell_1')
RCL_OWN = ('/rosout', '/parameter_events')  # rcl's own, shared by every node on the domain


class Cell:
    """One cell's graph in its namespace, with a run recorder."""

    def __init__(self, namespace: str, seed: int, folder):
        """Build the job's nodes (collaborative, unthrottled, job on its own) and a recorder."""
        self.namespace = namespace
        self.g = Graph(namespace)
        params = graph.job_params('collaborative')
        params['pybullet_bridge'].update(
            real_time_factor='0.0', item_seed=str(seed),
            lockstep_expect=graph.param_value(graph.lockstep_expect(graph.job_nodes())))
        params['automation_manager']['auto_start'] = 'true'
        self.nodes = {spec.name: self.g.add_node_of(spec.name, **params[spec.name])
                      for spec in graph.job_nodes()}
        self.recorder = self.g.add(RunRecorder(folder, 'collaborative', context=self.g.context,
                                               namespace=namespace))
        self.recorder.start_job(0.0)

    @property
    def bridge(self):
        """Return the cell's bridge node."""
        return self.nodes['pybullet_bridge']

    def sorted(self) -> int:
        """Return the items sorted, as both the job and the run's record have counted them."""
        return min(self.nodes['automation_manager'].job.counts.get('sorted', 0),
                   self.recorder.progress()['sorted'])

    def spin(self, seconds: float) -> None:
        """Spin the cell's executor for about ``seconds`` (wall)."""
        self.g.executor.spin_once(timeout_sec=seconds)

    def close(self) -> None:
        """Close the recorder's files, then the graph."""
        self.recorder.close()
        self.g.close()


@pytest.fixture
def cells(tmp_path):
    """Yield the two cells, closed afterwards."""
    made = []
    try:
        for k, ns in enumerate(CELLS):
            made.append(Cell(ns, seed=1 + k, folder=tmp_path / ns.strip('/')))
        yield made
    finally:
        for cell in made:
            cell.close()


def endpoints(node, name: str, namespace: str):
    """Return every topic a node publishes or subscribes (full names)."""
    pubs = node.get_publisher_names_and_types_by_node(name, namespace)
    subs = node.get_subscriber_names_and_types_by_node(name, namespace)
    return [t for t, _ in pubs + subs]


def test_two_cells_on_one_domain_each_sort_and_hear_nothing_of_the_other(cells):
    """Each cell sorts; its nodes' every topic is its own; clocks and locksteps apart."""
    first, second = cells
    # /cell_0 alone: its lockstep waits only for its own nodes (the others never answer)
    deadline = time.monotonic() + 60.0
    while first.bridge.sim.time < 2.0 and time.monotonic() < deadline:
        first.spin(0.001)
    assert first.bridge.sim.time >= 2.0, 'cell_0 waited for someone'
    assert second.bridge.sim.time == 0.0 and not first.bridge.gate.dropped
    assert sorted(first.bridge.gate.reached) == sorted(
        graph.resolve(n, '/cell_0') for n in graph.lockstep_expect(graph.job_nodes()))
    # both, until each has sorted an item
    deadline = time.monotonic() + 150.0
    while min(c.sorted() for c in cells) == 0 and time.monotonic() < deadline:
        for cell in cells:
            cell.spin(0.001)
    assert [c.sorted() > 0 for c in cells] == [True, True], [c.sorted() for c in cells]
    probe = first.g.probe
    for cell in cells:
        ns = cell.namespace
        # every endpoint of every node of the cell is in the cell (rclpy's /clock remapped)
        for name in list(graph.BY_NAME) + ['run_recorder']:
            if name not in cell.nodes and name != 'run_recorder':
                continue
            for topic in endpoints(probe, name, ns):
                assert topic.startswith(ns + '/') or topic in RCL_OWN, (ns, name, topic)
        # one clock per cell, the cell's own bridge; the root clock has none
        clock = graph.resolve(graph.CLOCK, ns)
        assert [(i.node_namespace, i.node_name) for i in probe.get_publishers_info_by_topic(
            clock)] == [(ns, 'pybullet_bridge')]
        subscribers = {i.node_namespace for i in probe.get_subscriptions_info_by_topic(clock)}
        assert subscribers == {ns}, subscribers
        # the lockstep: answers from this cell's nodes only, nobody dropped
        assert all(n.startswith(ns + '/') for n in cell.bridge.gate.reached)
        assert not cell.bridge.gate.dropped
        answering = {i.node_namespace for i in probe.get_publishers_info_by_topic(
            graph.resolve(lockstep.TOPIC, ns))}
        assert answering == {ns}
    # the root /clock has no publisher (asked by a node without the cells' /clock remap,
    # which rcl would apply to the query itself)
    root = first.g.add(Node('root_probe', context=first.g.context))
    assert root.get_publishers_info_by_topic('/clock') == []
    # the clocks are independent: each cell's sim time is its own
    assert first.bridge.sim.time != second.bridge.sim.time
    # the records: each sorted, no foreign clock, no second graph
    for cell in cells:
        cell.recorder.look()
        summary = cell.recorder.finish('duration reached', False, plots=False)
        assert summary['sorted'] > 0, summary
        assert summary['foreign_clocks'] == [] and summary['second_graphs'] == [], summary
        assert summary['graph_looks'] >= 1


def test_the_time_source_honours_the_clock_remap():
    """The time source of rclpy (``use_sim_time``) subscribes ``/clock``: the remap moves it."""
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    g = Graph('/cell_7')
    try:
        node = g.add(Node('timed', context=g.context, cli_args=graph.ros_args(
            namespace='/cell_7')))
        assert node.get_fully_qualified_name() == '/cell_7/timed'
        subs = [t for t, _ in node.get_subscriber_names_and_types_by_node('timed', '/cell_7')]
        assert subs == ['/cell_7/clock']
        pub = g.probe.create_publisher(Clock, graph.CLOCK, 10)  # the probe's: /cell_7/clock
        outside = g.add(Node('outside', context=g.context))  # the root, no remap
        root = outside.create_publisher(Clock, '/clock', 10)
        assert (pub.topic_name, root.topic_name) == ('/cell_7/clock', '/clock')

        def stepped():
            root.publish(Clock(clock=Time(sec=99)))
            pub.publish(Clock(clock=Time(sec=5)))
            return node.get_clock().now().nanoseconds > 0
        assert g.spin_until(stepped, 10.0)
        for _ in range(20):
            root.publish(Clock(clock=Time(sec=99)))
            g.spin_until(lambda: False, 0.01)
        assert node.get_clock().now().nanoseconds == 5 * 10**9
    finally:
        g.close()


def test_a_namespaced_probe_and_executor_are_separate_from_the_root():
    """Sanity of the harness: a probe in ``/cell_3`` resolves relative names there."""
    g = Graph('/cell_3')
    try:
        assert g.probe.get_fully_qualified_name() == '/cell_3/probe'
        assert isinstance(g.executor, SingleThreadedExecutor)
        assert g.probe.resolve_topic_name('joint_states') == '/cell_3/joint_states'
    finally:
        g.close()
