"""The arms' grippers in the simulator: grasp, release, and the payload the servo must know.

A grasp holds the item nearest the tool tip (its top centre within ``grasp_tolerance``) by a
fixed constraint at its current pose relative to the quill, so the arm feels its mass; the
computed-torque feed-forward adds it as payload (:attr:`Grippers.payload`). The items are the
:class:`~scara_collab.sim.conveyor.Conveyor`'s; a grasp and a release are its events.
"""
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np
import pybullet

from scara_collab.sim.conveyor import Conveyor, ItemRecord, PAYLOAD_CLASS
from scara_collab.sim.reference import robot_index

_CONSTRAINT_FORCE = 1e5  # N, the gripper's fixed constraint never slips


class Grippers:
    """One gripper per arm, by the arm's name.

    :param pb: the simulator's PyBullet client.
    :param conveyor: the items.
    :param cell_body: the cell's URDF body; :param quills: its quill link per arm.
    :param robots: the arms' names, in order.
    :param tolerance: m, the largest distance from the tool tip to an item's top centre that
        still grasps it.
    """

    def __init__(self, pb, conveyor: Conveyor, cell_body: int, quills: Sequence[int],
                 robots: Sequence[str], tolerance: float):
        """Start with every gripper open and empty."""
        self._pb, self.conveyor = pb, conveyor
        self._body, self._quill, self.robots = cell_body, list(quills), tuple(robots)
        self.tolerance = float(tolerance)
        self.held: List[Optional[int]] = [None] * len(self.robots)  # item id per arm
        self.payload = np.zeros(len(self.robots))  # kg held per arm (the servo's payload)

    def _index(self, robot: str) -> int:
        return robot_index(self.robots, robot)  # a TrajectoryError is a ValueError

    def tool_tip(self, robot: str) -> np.ndarray:
        """World position of the tool tip (the ``<robot>_quill`` link frame origin), ``(3,)``.

        :raises ValueError: for a robot the cell does not have.
        """
        state = self._pb.getLinkState(self._body, self._quill[self._index(robot)],
                                      computeForwardKinematics=True)
        return np.array(state[4])

    def held_item(self, robot: str) -> Optional[int]:
        """Id of the item in the gripper of ``robot``, or ``None``."""
        return self.held[self._index(robot)]

    def command(self, robot: str, grasp: bool) -> Tuple[bool, str]:
        """Grasp (``grasp`` true) or release, idempotently: what the gripper service does.

        A grasp while holding an item and a release while empty succeed and change nothing,
        so a repeated request (its answer was lost) is never an error.

        :return: ``(ok, message)`` as :meth:`grasp` / :meth:`release`.
        """
        try:
            held = self.held_item(robot)
        except ValueError as exc:
            return False, str(exc)
        if grasp and held is not None:
            return True, f'{robot} already holds item {held}'
        if not grasp and held is None:
            return True, f'{robot} holds nothing (already released)'
        return self.grasp(robot) if grasp else self.release(robot)

    def _attach(self, a: int, rec: ItemRecord) -> None:
        pb = self._pb
        link = pb.getLinkState(self._body, self._quill[a], computeForwardKinematics=True)
        inv_pos, inv_orn = pb.invertTransform(link[0], link[1])
        pos, orn = pb.getBasePositionAndOrientation(rec.body)
        rel_pos, rel_orn = pb.multiplyTransforms(inv_pos, inv_orn, pos, orn)
        cid = pb.createConstraint(self._body, self._quill[a], rec.body, -1, pybullet.JOINT_FIXED,
                                  [0.0, 0.0, 0.0], rel_pos, [0.0, 0.0, 0.0], rel_orn,
                                  [0.0, 0.0, 0.0, 1.0])
        pb.changeConstraint(cid, maxForce=_CONSTRAINT_FORCE)
        pb.setCollisionFilterPair(self._body, rec.body, self._quill[a], -1, 0)
        rec.constraint, rec.holder, rec.state = cid, self.robots[a], 'held'
        rec.last_robot = self.robots[a]
        self.held[a] = rec.id
        self.payload[a] = rec.mass

    def grasp(self, robot: str) -> Tuple[bool, str]:
        """Attach the item whose top centre is nearest ``robot``'s tool tip.

        :return: ``(True, message)``, or ``(False, reason)`` for an unknown robot, a gripper
            that already holds an item, or nothing within the tolerance.
        """
        try:
            a = self._index(robot)
        except ValueError as exc:
            return False, str(exc)
        tip = self.tool_tip(robot)
        if self.held[a] is not None:
            return False, f'{robot} already holds item {self.held[a]}'
        half = self.conveyor.cell.item_size / 2.0
        best, best_d = None, math.inf
        for rec in self.conveyor.records.values():
            if rec.state == 'held':
                continue
            x, y, z = self._pb.getBasePositionAndOrientation(rec.body)[0]
            d = math.dist((x, y, z + half), tip)
            if d < best_d:
                best, best_d = rec, d
        if best is None or best_d > self.tolerance:
            near = '' if best is None else f'; the nearest item top is {best_d:.3f} m away'
            return False, (f'nothing to grasp within {self.tolerance} m of the {robot} tool '
                           f'tip{near}')
        self._attach(a, best)
        self.conveyor.event('grasped', best, robot)
        return True, f'{robot} grasped item {best.id} ({best.cls}) at {best_d * 1000:.1f} mm'

    def release(self, robot: str) -> Tuple[bool, str]:
        """Open the gripper of ``robot``: the held item falls free.

        :return: ``(True, message)``, or ``(False, reason)`` for an unknown robot or a gripper
            that holds nothing.
        """
        try:
            a = self._index(robot)
        except ValueError as exc:
            return False, str(exc)
        item_id = self.held[a]
        if item_id is None:
            return False, f'{robot} holds nothing to release'
        rec = self.conveyor.records[item_id]
        self._pb.removeConstraint(rec.constraint)
        self._pb.setCollisionFilterPair(self._body, rec.body, self._quill[a], -1, 1)
        rec.constraint, rec.holder, rec.state = None, None, 'free'
        self.held[a] = None
        self.payload[a] = 0.0
        self.conveyor.event('released', rec, robot)
        return True, f'{robot} released item {rec.id} ({rec.cls})'

    def slip(self, robot: str) -> Optional[int]:
        """Let the item ``robot`` holds slip out of its gripper (an event ``slipped``).

        :return: the item's id, or None if the gripper holds nothing.
        """
        item_id = self.held_item(robot)
        if item_id is None:
            return None
        self.release(robot)
        self.conveyor.event('slipped', self.conveyor.records[item_id], robot)
        return item_id

    def attach_payload(self, robot: str, mass: float, size: Optional[float] = None) -> int:
        """Hang a test body of ``mass`` kg (a cube, class ``'payload'``) on ``robot``'s tool.

        Its top centre is placed at the tool tip and it is held like a grasped
        item, so the physics feels it and the computed-torque feed-forward knows it. For
        benchmarks.

        :param size: cube edge, m; default the item size.
        :return: the body's item id (``release`` drops it).
        :raises ValueError: for an unknown robot, a mass or size <= 0, or a gripper that
            already holds something.
        """
        a = self._index(robot)
        size = self.conveyor.cell.item_size if size is None else float(size)
        if not (math.isfinite(mass) and mass > 0 and math.isfinite(size) and size > 0):
            raise ValueError(f'payload mass and size must be > 0, got {mass!r} kg, {size!r} m')
        if self.held[a] is not None:
            raise ValueError(f'{self.robots[a]} already holds item {self.held[a]}')
        rec = self.conveyor.create_item(PAYLOAD_CLASS,
                                        self.tool_tip(robot) - [0.0, 0.0, size / 2.0],
                                        float(mass), 'held', size)
        self._attach(a, rec)
        return rec.id
