"""The sorting job's settings, without ROS: its modes and its tuning.

Every part of the job reads them (:mod:`scara_collab.core.job`, :mod:`scara_collab.core.lanes`,
:mod:`scara_collab.core.sharing`); they import nothing of the job.
"""
from dataclasses import dataclass
from typing import Optional

from scara_collab.core import sorting
from scara_collab.core.config import load_config
from scara_collab.core.model import CellModel
from scara_collab.core.move_time import Leads

MODES = ('single', 'collaborative', 'mirrored')


@dataclass(frozen=True)
class JobSettings:
    """The job's tuning, from ``config/automation.yaml`` (see that file for the meanings)."""

    mode: str
    pick_z: float
    carry_z: float
    drop_clearance: float
    grasp_reach: float
    answer_timeout: float
    answer_retries: int
    move_timeout: float
    carry_timeout: float
    arrive_timeout: float
    arrive_tolerance: float
    grip_timeout: float
    grip_retries: int
    pair_offset: float = 0.0
    pair_margin: float = 0.13
    unblock_after: float = 0.5
    bin_retries: int = 3
    steal_cycle: float = 0.0
    #: the start rule's leads (``decision``, ``move``, ``pair``)
    leads: Leads = Leads()
    line_cell: int = 0
    line_cells: int = 1
    line_capacity: float = 40.0
    #: the speed factor a meeting with an item is taken at without looking further, near a
    #: person (below it, a later meeting down the belt may be faster)
    person_speed: float = 0.9
    #: the least speed factor a meeting is taken at, near a person (below: left for the person)
    person_least_speed: float = 0.3
    #: m kept beyond the protective separation when that meeting is chosen
    person_buffer: float = 0.3

    @staticmethod
    def from_config(cell: CellModel, cfg: dict, mode: Optional[str] = None,
                    controllers: Optional[dict] = None) -> 'JobSettings':
        """Build the settings from the ``automation`` config tree (``mode`` overrides).

        :param controllers: the ``controllers`` config tree (default ``controllers.yaml``), the
            planners' settings: mirrored pairs are checked against the planners' margin
            (safety margin + ``planning_buffer``), and a move asked for as soon as possible
            is asked with the planners' lead (:class:`~scara_collab.core.move_time.Leads`).
        :raises ValueError: a mode not in :data:`MODES`.
        """
        controllers = load_config('controllers') if controllers is None else controllers
        mode = mode or cfg['mode']
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        if not 0 <= int(cfg['line_cell']) < int(cfg['line_cells']):
            raise ValueError(f"line_cell {cfg['line_cell']} is not a cell of a line of "
                             f"{cfg['line_cells']}")
        pick_z = sorting.pick_height(cell, cfg['pick_clearance'])
        # a held item hangs item_size + pick_clearance below the tool: lifted to carry_z, its
        # bottom clears the tops of the items on the belt by carry_clearance
        carry_z = (pick_z + cell.item_size + float(cfg['carry_clearance'])
                   if cfg['lift_after_grasp'] else pick_z)
        return JobSettings(
            mode=mode, pick_z=pick_z, carry_z=carry_z,
            drop_clearance=float(cfg['drop_clearance']), grasp_reach=float(cfg['grasp_reach']),
            answer_timeout=float(cfg['answer_timeout']), answer_retries=int(cfg['answer_retries']),
            move_timeout=float(cfg['move_timeout']), carry_timeout=float(cfg['carry_timeout']),
            arrive_timeout=float(cfg['arrive_timeout']),
            arrive_tolerance=float(cfg['arrive_tolerance']),
            grip_timeout=float(cfg['grip_timeout']), grip_retries=int(cfg['grip_retries']),
            pair_offset=float(cfg['mirror_pair_offset']),
            unblock_after=float(cfg['unblock_after']),
            steal_cycle=float(cfg['steal_cycle']),
            pair_margin=cell.safety_margin + float(controllers['planning_buffer']),
            leads=Leads.of(cfg, controllers),
            line_cell=int(cfg['line_cell']), line_cells=int(cfg['line_cells']),
            line_capacity=float(cfg['line_capacity']),
            person_speed=float(cfg['person_speed']),
            person_least_speed=float(cfg['person_least_speed']),
            person_buffer=float(cfg['person_buffer']))
