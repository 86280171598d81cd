"""The graph's named QoS profiles, defined once."""
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

#: latched state (``/emergency_stop``): a late subscriber gets the last value
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
#: only the newest message matters (joint states for planning: a backlog would be stale)
LATEST = QoSProfile(depth=1)
#: a stream to keep whole (events, statuses)
EVENTS = QoSProfile(depth=100)
