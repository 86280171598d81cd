"""The nodes that decide on sim time take every joint state, in order.

docs/realtime.md, *Repeatable runs*: the same seed gives the same run.

With a queue of one, the callback of a state takes the newest one: when a node is a state
behind (busy, descheduled), it sees the state after the next ``/clock`` before that clock's
tick, or not, by timing, and two runs of the same seed part as separate processes.
"""
import rclpy
from ros_harness import params_args

from scara_collab import graph

DECIDERS = ('left_planner', 'right_planner', 'collision_monitor', 'automation_manager')


def test_every_decider_keeps_a_window_of_states():
    """Job, planners and monitor queue more joint states than one lockstep window brings."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    nodes = []
    try:
        for spec in graph.job_nodes():
            if spec.name in DECIDERS:
                nodes.append(spec.build(context=ctx, cli_args=params_args(
                    *spec.configs, overrides={'use_sim_time': 'true'})))
        depths = {n.get_name(): [s.qos_profile.depth for s in n.subscriptions
                                 if s.topic_name == '/joint_states'] for n in nodes}
        assert sorted(depths) == sorted(DECIDERS)
        # 100 Hz states, a 20 ms window: two a window, three before the node is a window late
        assert all(d and min(d) >= 3 for d in depths.values()), depths
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.shutdown(context=ctx)
