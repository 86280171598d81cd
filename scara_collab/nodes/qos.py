"""The graph's named QoS profiles as rclpy profiles, made once from :data:`graph.QOS`.

A publisher takes its topic's profile (:func:`of`; most are :data:`DEFAULT`), a subscriber
the profile it needs: the newest state only (:data:`LATEST`), a whole stream
(:data:`EVENTS`), the latched state (:data:`LATCHED`), or a recorder's deep queue
(:func:`recording`).

>>> of('/emergency_stop') == LATCHED, LATCHED.durability.name
(True, 'TRANSIENT_LOCAL')
>>> recording(graph.topic('/clock')).depth, recording(graph.topic('/emergency_stop')).depth
(200, 1)
"""
from typing import Dict

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from scara_collab import graph


def _profile(spec: graph.Qos) -> QoSProfile:
    if spec.latched:
        return QoSProfile(depth=spec.depth, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          reliability=ReliabilityPolicy.RELIABLE)
    return QoSProfile(depth=spec.depth)  # reliable, volatile


#: every profile of :data:`scara_collab.graph.QOS`, by name
PROFILES: Dict[str, QoSProfile] = {name: _profile(spec) for name, spec in graph.QOS.items()}
#: most topics (states, targets, statuses): rclpy's usual keep-last 10, reliable, volatile
DEFAULT = PROFILES['default']
#: latched state (``/emergency_stop``): a late subscriber gets the last value
LATCHED = PROFILES['latched']
#: only the newest message matters (the TF publisher: a backlog of states would be stale)
LATEST = PROFILES['latest']
#: a stream to keep whole (events, statuses)
EVENTS = PROFILES['events']


def of(name: str) -> QoSProfile:
    """Return the profile the graph gives the topic ``name`` (its publisher's)."""
    return PROFILES[graph.topic(name).qos]


def recording(topic: graph.Topic) -> QoSProfile:
    """Return how a recorder subscribes ``topic``: latched if it is, else a deep queue."""
    return LATCHED if topic.latched else PROFILES['recording']
