"""The cell's description and transforms for a recording, made from its joint states.

A recording that holds ``/robot_description``, ``/tf_static`` and ``/tf`` shows the arms moving
in Foxglove or RViz. The recorder does not need ``tf2_msgs`` (no PyPI wheel) or a state
publisher for that: :class:`Transforms` serialises them itself, with the message definitions
written here where the package is not installed, from the cell's URDF
(:mod:`scara_collab.core.frames`) and every recorded ``/joint_states`` (CDR in, CDR out).
"""
from typing import Dict, List, Tuple

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from scara_collab.core.frames import quaternion, Tree
from scara_collab.graph import Topic

TF_TYPE = 'tf2_msgs/msg/TFMessage'
STATE_TYPE = 'sensor_msgs/msg/JointState'
DESCRIPTION_TYPE = 'std_msgs/msg/String'
#: the recording's derived topics, with their publishers' QoS as robot_state_publisher's
TOPICS = (Topic('/robot_description', DESCRIPTION_TYPE, 'latched'),
          Topic('/tf_static', TF_TYPE, 'latched'), Topic('/tf', TF_TYPE))
#: tf2_msgs/msg/TFMessage (Jazzy), for a recorder without tf2_msgs installed
TF_DEFINITION = 'geometry_msgs/TransformStamped[] transforms\n'
#: its REP-2011 type hash in Jazzy (checked by test/test_interfaces.py against the built one)
TF_HASH = 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'


def _stamp(seconds: int, nanoseconds: int) -> Dict[str, int]:
    return {'sec': int(seconds), 'nanosec': int(nanoseconds)}


def _transforms(items, stamp: Dict[str, int]) -> Dict[str, object]:
    out = []
    for parent, child, pose in items:
        x, y, z, w = quaternion(pose[:3, :3])
        out.append({'header': {'stamp': stamp, 'frame_id': parent}, 'child_frame_id': child,
                    'transform': {'translation': dict(zip('xyz', map(float, pose[:3, 3]))),
                                  'rotation': {'x': x, 'y': y, 'z': z, 'w': w}}})
    return {'transforms': out}


class Transforms:
    """Serialised description, static and moving transforms of the cell (module docstring).

    :param urdf: the cell's URDF (:attr:`scara_collab.core.model.CellModel.urdf`).
    :param definitions: the concatenated ``ros2msg`` definitions of ``DESCRIPTION_TYPE``,
        ``STATE_TYPE`` and ``TF_TYPE`` by type (as the recording's schemas hold them).
    """

    def __init__(self, urdf: str, definitions: Dict[str, str]):
        """Parse the URDF's tree and make the encoders and the joint-state decoder."""
        self.urdf, self.tree = urdf, Tree.of(urdf)
        self._encode = {t: serialize_dynamic(t, definitions[t])[t]
                        for t in (TF_TYPE, DESCRIPTION_TYPE)}
        self._decode = generate_dynamic(STATE_TYPE, definitions[STATE_TYPE])[STATE_TYPE]
        self._joints = set(self.tree.moving_joints)

    def first(self) -> List[Tuple[str, bytes]]:
        """Return ``(topic, CDR)`` of the description and the static transforms (stamped 0)."""
        return [('/robot_description', self._encode[DESCRIPTION_TYPE]({'data': self.urdf})),
                ('/tf_static', self._encode[TF_TYPE](
                    _transforms(self.tree.static(), _stamp(0, 0))))]

    def from_state(self, data: bytes) -> bytes:
        """Return the ``/tf`` CDR of a ``/joint_states`` CDR, stamped like it (b'' if unusable).

        Joints of the state that are not the tree's are left out; a state with none is unusable.
        """
        try:
            state = self._decode(data)
        except Exception:  # noqa: B902 - a malformed message is recorded as it came, no /tf
            return b''
        positions = {n: p for n, p in zip(state.name, state.position) if n in self._joints}
        if not positions:
            return b''
        stamp = _stamp(state.header.stamp.sec, state.header.stamp.nanosec)
        return self._encode[TF_TYPE](_transforms(self.tree.moving(positions), stamp))
