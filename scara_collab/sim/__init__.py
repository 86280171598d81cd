"""The simulation layer: the PyBullet cell (:class:`CellSim`), its servo laws and references.

No rclpy here; the ``pybullet_bridge`` node wraps :class:`CellSim` in topics and services.
"""
from scara_collab.sim.cell_sim import CellSim, Item, JointStateSample, SimEvent
from scara_collab.sim.reference import TrajectoryError

__all__ = ['CellSim', 'Item', 'JointStateSample', 'SimEvent', 'TrajectoryError']
