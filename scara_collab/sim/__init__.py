"""The simulation layer: the PyBullet cell (:class:`CellSim`), conveyor, servo laws, references.

No rclpy here; the ``pybullet_bridge`` node wraps :class:`CellSim` in topics and services.
"""
from scara_collab.sim.cell_sim import CellSim, JointStateSample
from scara_collab.sim.conveyor import Conveyor, Item, SimEvent
from scara_collab.sim.reference import TrajectoryError

__all__ = ['CellSim', 'Conveyor', 'Item', 'JointStateSample', 'SimEvent', 'TrajectoryError']
