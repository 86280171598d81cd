#!/usr/bin/env python3
"""Check the interface packages that scripts/build_interfaces builds into a venv.

Imports tf2_msgs/msg/TFMessage and control_msgs/action/FollowJointTrajectory, publishes and
receives one TFMessage, and runs one FollowJointTrajectory goal through an rclpy ActionServer
and ActionClient in this process (feedback, then result). It also checks that the type hashes
the middleware announces are ROS 2 Jazzy's, so other Jazzy nodes (RViz, Foxglove, controllers)
match these types. Exits 0 when all of that works, 1 (with the reason) when not; every wait has
a timeout.

Usage: .venv/bin/python scripts/check_interfaces.py [--timeout SECONDS]
Run it with ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE set as for the tests, to stay off
other machines' graphs.
"""
import argparse
import os
import signal
import sys
import threading
import time

# The type hashes (RIHS01) of ROS 2 Jazzy's definitions; they cover field names, types and
# order of the type and of every type it refers to.
JAZZY_HASHES = {
    'tf2_msgs/msg/TFMessage':
        'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087',
    'control_msgs/action/FollowJointTrajectory_FeedbackMessage':
        'RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71',
}


class CheckFailed(Exception):
    """A step of the check did not work."""


def wait_for(predicate, timeout, what):
    """Poll ``predicate`` every 20 ms until it is true; raise CheckFailed after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise CheckFailed(f'timed out after {timeout:.0f} s waiting for {what}')
        time.sleep(0.02)


def announced_hash(node, topic):
    """Return the type hash that the publishers of ``topic`` announce, as a string."""
    infos = node.get_publishers_info_by_topic(topic)
    return str(infos[0].topic_type_hash) if infos else None


def check_hash(node, topic, type_name, timeout):
    """Wait until ``topic`` has a publisher and check that its type hash is Jazzy's."""
    wait_for(lambda: announced_hash(node, topic) is not None, timeout, f'a publisher on {topic}')
    got = announced_hash(node, topic)
    if got != JAZZY_HASHES[type_name]:
        raise CheckFailed(f'{type_name} has type hash {got}, Jazzy has '
                          f'{JAZZY_HASHES[type_name]}: its definition is not the Jazzy one')
    print(f'check_interfaces: {type_name} type hash matches Jazzy ({got[:19]}...)')


def check_tf(node, timeout):
    """Publish TFMessages until one arrives at a subscription of the same node."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    topic = 'check_interfaces/tf'
    received = []
    node.create_subscription(TFMessage, topic, received.append, 10)
    pub = node.create_publisher(TFMessage, topic, 10)
    sent = TFMessage(transforms=[TransformStamped()])
    sent.transforms[0].header.frame_id = 'world'
    sent.transforms[0].child_frame_id = 'left_base'
    sent.transforms[0].transform.translation.x = -0.35
    sent.transforms[0].transform.rotation.w = 1.0
    deadline = time.monotonic() + timeout
    while not received:
        if time.monotonic() > deadline:
            raise CheckFailed(f'no TFMessage came back on {topic} within {timeout:.0f} s')
        pub.publish(sent)
        time.sleep(0.1)
    got = received[0]
    if got != sent:
        raise CheckFailed(f'TFMessage came back changed: {got}')
    print(f'check_interfaces: TFMessage published and received on /{topic} '
          f'({got.transforms[0].header.frame_id} -> {got.transforms[0].child_frame_id})')
    check_hash(node, '/' + topic, 'tf2_msgs/msg/TFMessage', timeout)


def check_action(node, timeout):
    """Run one FollowJointTrajectory goal: server and client in this node."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance, JointTolerance
    from rclpy.action import ActionClient, ActionServer
    from rclpy.callback_groups import ReentrantCallbackGroup
    from trajectory_msgs.msg import JointTrajectoryPoint

    name = 'check_interfaces/follow_joint_trajectory'
    feedback_seen = threading.Event()
    group = ReentrantCallbackGroup()

    def execute(goal_handle):
        goal = goal_handle.request
        points = goal.trajectory.points
        feedback = FollowJointTrajectory.Feedback()
        feedback.joint_names = list(goal.trajectory.joint_names)
        feedback.desired = points[-1]
        feedback.actual = JointTrajectoryPoint(positions=[0.0] * len(feedback.joint_names))
        feedback.error = JointTrajectoryPoint(positions=list(points[-1].positions))
        # Feedback goes out on a topic: repeat it until the client has seen one.
        deadline = time.monotonic() + timeout
        while not feedback_seen.is_set() and time.monotonic() < deadline:
            goal_handle.publish_feedback(feedback)
            feedback_seen.wait(0.1)
        result = FollowJointTrajectory.Result()
        tol = goal.component_goal_tolerance
        if (not feedback_seen.is_set() or goal.path_tolerance[0].name != 'left_j1'
                or tol[0].component != JointComponentTolerance.ROTATION):
            goal_handle.abort()
            result.error_code = FollowJointTrajectory.Result.INVALID_GOAL
            result.error_string = 'goal arrived changed, or the feedback was not seen'
            return result
        goal_handle.succeed()
        result.error_code = FollowJointTrajectory.Result.SUCCESSFUL
        joints = len(feedback.joint_names)
        result.error_string = f'followed {len(points)} points on {joints} joints'
        return result

    server = ActionServer(node, FollowJointTrajectory, name, execute_callback=execute,
                          callback_group=group)
    client = ActionClient(node, FollowJointTrajectory, name, callback_group=group)
    try:
        if not client.wait_for_server(timeout_sec=timeout):
            raise CheckFailed(
                f'the FollowJointTrajectory server did not appear in {timeout:.0f} s')
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = ['left_j1', 'left_j2', 'left_j3', 'left_j4']
        goal.trajectory.points = [
            JointTrajectoryPoint(positions=[0.0, 0.0, 0.0, 0.0],
                                 time_from_start=Duration(sec=0)),
            JointTrajectoryPoint(positions=[0.4, -0.3, 0.05, 0.1],
                                 time_from_start=Duration(sec=1)),
        ]
        goal.path_tolerance = [JointTolerance(name='left_j1', position=0.05)]
        goal.component_goal_tolerance = [JointComponentTolerance(
            joint_name='left_j1', component=JointComponentTolerance.ROTATION, position=0.01)]
        goal.goal_time_tolerance = Duration(sec=0, nanosec=500_000_000)

        feedback_msgs = []

        def on_feedback(msg):
            feedback_msgs.append(msg.feedback)
            feedback_seen.set()

        send = client.send_goal_async(goal, feedback_callback=on_feedback)
        wait_for(send.done, timeout, 'the goal to be accepted')
        handle = send.result()
        if not handle.accepted:
            raise CheckFailed('the FollowJointTrajectory goal was rejected')
        get_result = handle.get_result_async()
        wait_for(get_result.done, timeout, 'the FollowJointTrajectory result')
        result = get_result.result().result
        if not feedback_msgs:
            raise CheckFailed('no FollowJointTrajectory feedback arrived')
        if result.error_code != FollowJointTrajectory.Result.SUCCESSFUL:
            raise CheckFailed(f'FollowJointTrajectory failed: error_code {result.error_code}, '
                              f'{result.error_string!r}')
        print(f'check_interfaces: FollowJointTrajectory goal accepted, {len(feedback_msgs)} '
              f'feedback (joints {", ".join(feedback_msgs[0].joint_names)}), result '
              f'SUCCESSFUL: {result.error_string}')
        check_hash(node, f'/{name}/_action/feedback',
                   'control_msgs/action/FollowJointTrajectory_FeedbackMessage', timeout)
    finally:
        client.destroy()
        server.destroy()


def _too_long(*_):
    print('check_interfaces: FAILED: the whole check took too long', file=sys.stderr, flush=True)
    os._exit(1)


def main(argv=None) -> int:
    """Run the checks; return 0 if all passed, else 1."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--timeout', type=float, default=20.0,
                        help='seconds each wait may take (default 20)')
    args = parser.parse_args(argv)
    # A hard stop, in case rclpy itself hangs (e.g. in shutdown).
    signal.signal(signal.SIGALRM, _too_long)
    signal.alarm(int(6 * args.timeout) + 10)
    started = time.monotonic()
    try:
        from control_msgs.action import FollowJointTrajectory  # noqa: F401
        from tf2_msgs.msg import TFMessage  # noqa: F401
    except ImportError as exc:
        print(f'check_interfaces: FAILED: {exc}; run scripts/build_interfaces for this venv '
              f'({sys.prefix})', file=sys.stderr)
        return 1
    print('check_interfaces: imported tf2_msgs.msg.TFMessage and '
          'control_msgs.action.FollowJointTrajectory')

    import rclpy
    from rclpy.executors import MultiThreadedExecutor

    rclpy.init()
    node = rclpy.create_node('check_interfaces')
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        check_tf(node, args.timeout)
        check_action(node, args.timeout)
    except CheckFailed as exc:
        print(f'check_interfaces: FAILED: {exc}', file=sys.stderr)
        return 1
    finally:
        executor.shutdown(timeout_sec=5)
        node.destroy_node()
        rclpy.try_shutdown()
        spinner.join(timeout=5)
    print(f'check_interfaces: ok ({time.monotonic() - started:.1f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
