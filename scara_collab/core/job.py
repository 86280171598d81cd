"""The sorting job as a state machine, without ROS: observations in, commands out.

:class:`SortingJob` decides everything the automation manager does; the node only turns
messages into the ``on_*`` observations, calls :meth:`SortingJob.tick` on a timer and turns
the returned :class:`MoveCommand` / :class:`GripCommand` into messages and service calls.

A *lane* is one arm's work (``single``: the leader; ``collaborative``: one lane per arm;
``mirrored``: one lane that moves both arms, the follower to the mirror image). Its phases:

=============  =================================================  ===========================
phase          leaves when                                        deadline (then)
=============  =================================================  ===========================
``idle``       an item can be met: a pick move is asked           none
``to_item``    every arm's move has arrived (bridge ``finished``  no planner answer:
               or the end time passed with the tool at the        ``answer_timeout``, re-sent
               target): grasp if the item is under the tool,      ``answer_retries`` times;
               else chase it or give up                           not planned by
                                                                  ``move_timeout``; not
                                                                  arrived ``arrive_timeout``
                                                                  after its end (give up,
                                                                  park)
``grasping``   every gripper answered (or the bridge's            ``grip_timeout``, asked
               ``grasped`` event confirmed it)                    again ``grip_retries`` times
                                                                  (give up)
``lift``       as ``to_item``; only when ``carry_height`` lifts   as ``to_item``
               the item above those on the belt
``to_bin``     as ``to_item``                                     as ``to_item`` with
                                                                  ``carry_timeout``; a given
                                                                  up bin move is asked again
``releasing``  every gripper answered (or ``released`` seen)      as ``grasping``
``to_park``    as ``to_item``                                     as ``to_item`` (then idle)
=============  =================================================  ===========================

Every observation names what it is about (a move by its request, a grip by its token), so a
late, duplicated or unknown one is ignored, and every waiting phase has a deadline, so a lost
one costs a retry, never the run. The servers are idempotent (a planner re-publishes the status
of a request it already has; a grasp while holding and a release while empty succeed), so a
re-sent request is always safe. Each move goes out with the job's plan of it (the one it
was chosen by), which the planner schedules without planning it again. That protocol is
:class:`scara_collab.core.lanes.LaneProtocol`; :class:`SortingJob` adds the decisions: which
item an arm takes and when (ranked by :func:`scara_collab.core.sorting.rank_by_cycle`), what
follows each arrival and grip, how the two arms share the belt (:mod:`scara_collab.core.pairing`).
"""
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import pairing, sharing, sorting
from scara_collab.core.lanes import (FAILED_MOVE, GripCommand, GripTrack, Lane, MOVE_STATES,
                                     MoveCommand, MoveTrack, MOVING, PHASES, PlanFn)
from scara_collab.core.model import CellModel
from scara_collab.core.sharing import SharedBelt

__all__ = ['FAILED_MOVE', 'GripCommand', 'GripTrack', 'ItemNotes',
           'items_per_minute', 'JobSettings', 'Lane', 'LOOK_AGAIN', 'MODES', 'MOVE_STATES',
           'MoveCommand', 'MoveTrack', 'MOVING', 'PHASES', 'SAVABLE', 'SortingJob']

MODES = ('single', 'collaborative', 'mirrored')
#: s an idle arm that found nothing to take waits before it looks again (the items move 2 cm)
LOOK_AGAIN = 0.1
#: urgent items an arm can still save by taking them first, most urgent first; with more, the
#: feed is faster than the arm and it takes the item that makes the shortest cycle
SAVABLE = 2


def items_per_minute(sorted_count: int, seconds: float) -> float:
    """Items sorted per minute over a window of ``seconds`` (0 for an empty window).

    The one definition used by the job's stats, the run summary and the benchmarks: the
    window starts when the feed starts (the job's start) and ends at the run's end.

    >>> items_per_minute(30, 60.0)
    30.0
    """
    return 60.0 * sorted_count / seconds if seconds > 0 else 0.0


@dataclass(frozen=True)
class JobSettings:
    """The job's tuning, from ``config/automation.yaml`` (see that file for the meanings)."""

    mode: str
    pick_z: float
    carry_z: float
    drop_clearance: float
    grasp_reach: float
    decision_lead: float
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
    pair_lead: float = 0.1
    unblock_after: float = 0.5
    bin_retries: int = 3
    steal_cycle: float = 0.0

    @staticmethod
    def from_config(cell: CellModel, cfg: dict, mode: Optional[str] = None,
                    planning_buffer: float = 0.03) -> 'JobSettings':
        """Build the settings from the ``automation`` config tree (``mode`` overrides).

        :param planning_buffer: ``controllers.yaml`` ``planning_buffer``: mirrored pairs are
            checked against the planners' margin (safety margin + this).
        """
        mode = mode or cfg['mode']
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        pick_z = sorting.pick_height(cell, cfg['pick_clearance'])
        # a held item hangs item_size + pick_clearance below the tool: lifted to carry_z, its
        # bottom clears the tops of the items on the belt by carry_clearance
        carry_z = (pick_z + cell.item_size + float(cfg['carry_clearance'])
                   if cfg['lift_after_grasp'] else pick_z)
        return JobSettings(
            mode=mode, pick_z=pick_z, carry_z=carry_z,
            drop_clearance=float(cfg['drop_clearance']), grasp_reach=float(cfg['grasp_reach']),
            decision_lead=float(cfg['decision_lead']),
            answer_timeout=float(cfg['answer_timeout']), answer_retries=int(cfg['answer_retries']),
            move_timeout=float(cfg['move_timeout']), carry_timeout=float(cfg['carry_timeout']),
            arrive_timeout=float(cfg['arrive_timeout']),
            arrive_tolerance=float(cfg['arrive_tolerance']),
            grip_timeout=float(cfg['grip_timeout']), grip_retries=int(cfg['grip_retries']),
            pair_offset=float(cfg['mirror_pair_offset']),
            pair_lead=float(cfg['mirror_start_lead']),
            unblock_after=float(cfg['unblock_after']),
            steal_cycle=float(cfg['steal_cycle']),
            pair_margin=cell.safety_margin + float(planning_buffer))


class ItemNotes:
    """The job's last word on each item on the belt, so that a missed item says why.

    Kept per item until it leaves the belt: ranked among an arm's candidates, not met (no
    intercept, or the way not clear), claimed, given up.
    """

    def __init__(self):
        """No item noted yet."""
        self._notes: Dict[int, str] = {}

    def note(self, item: int, now: float, text: str) -> None:
        """Note ``text`` about ``item`` at sim time ``now``."""
        self._notes[item] = f'{text} at t={now:.2f} s'

    def ranked(self, robot: str, order: Sequence, now: float) -> None:
        """Note each item's place among ``robot``'s candidates (``(group, item)`` pairs)."""
        for k, (_, item) in enumerate(order):
            self.note(item.id, now, f'{robot} ranked it #{k + 1} of {len(order)}')

    def close(self, item: int) -> str:
        """Forget ``item`` (it left the belt); return the last note, or say there was none."""
        return self._notes.pop(item, 'never a candidate of either arm')


class SortingJob(SharedBelt):
    """The sorting job's decisions (see the module docstring).

    :param cell: the cell model.
    :param settings: the tuning (:meth:`JobSettings.from_config`).
    :param plan: ``plan(robot, q_start, target) -> Trajectory`` with the planners' settings
        (raises ``ValueError`` if refused): the job times intercepts with the planners' own
        trajectories.
    :param log: ``log(level, text)`` for decisions worth a log line (``'info'``, ``'warn'``).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn,
                 log: Callable[[str, str], None] = lambda level, text: None):
        """Set up one lane per arm that moves on its own (one for a mirrored pair); not started."""
        lead, foll = cell.leader, cell.follower
        lanes = {'single': [(lead.name, (lead.name,))],
                 'collaborative': [(lead.name, (lead.name,)), (foll.name, (foll.name,))],
                 'mirrored': [(lead.name, (lead.name, foll.name))]}[settings.mode]
        super().__init__(cell, settings, lanes, plan, log)
        self.running = False
        self.estop = False
        self.start_time: Optional[float] = None
        self.items: Dict[int, sorting.SeenItem] = {}
        self.claimed: Dict[int, str] = {}
        self.counts: Dict[str, int] = {}
        self.sorted_by: Dict[str, int] = {a.name: 0 for a in cell.arms}
        self.give_ups = 0
        self.last_give_up = ''
        self.notes = ItemNotes()

    # --- observations ---------------------------------------------------------------------
    def start(self, now: float) -> bool:
        """Run the job (idempotent); return False if it was already running."""
        if self.running:
            return False
        self.running = True
        if self.start_time is None:
            self.start_time = now
        return True

    def stop(self) -> bool:
        """Stop taking new items (idempotent); arms holding an item still bring it to its bin."""
        was, self.running = self.running, False
        return was

    def on_items(self, items: Sequence[sorting.SeenItem]) -> None:
        """Take the items resting on the belt now (not held, not falling, not in a bin)."""
        self.items = {it.id: it for it in items}

    def on_estop(self, on: bool) -> None:
        """Take the emergency stop: while set, nothing new is commanded."""
        self.estop = bool(on)

    def on_item_event(self, kind: str, item: int, robot: str) -> None:
        """Count a bridge item event; it also confirms grasps and releases."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind == 'sorted' and robot in self.sorted_by:
            self.sorted_by[robot] += 1
        if kind in ('sorted', 'wrong_bin', 'missed', 'dropped'):
            self.claimed.pop(item, None)
            last = self.notes.close(item)
            if kind == 'missed':
                self.log('warn', f'item {item} missed; last: {last}')
        self._confirm_grip(kind, robot)

    # --- the clock ------------------------------------------------------------------------
    def tick(self, now: float) -> List[object]:
        """Advance every lane to ``now`` (sim s); return the commands to send, in order."""
        self._out = []
        self._now = now
        self.plan.forget()
        if self.estop or len(self.q) < len(self.cell.arms):
            self._held = []  # nothing new is commanded; a lane re-sends after answer_timeout
            return self._out
        if self.running and not self._parked_unused:
            self._park_unused(now)
        for lane in self.lanes:
            if lane.phase == 'idle':
                if self.running and now >= lane.next_look:
                    self._pick_next(lane, now)
            elif lane.phase in MOVING:
                self._tick_move(lane, now)
            else:
                self._tick_grip(lane, now)
        if len(self.lanes) > 1:
            self._unblock(now)
        return self._in_turn(self._out, now)

    # --- after a move -----------------------------------------------------------------------
    def _arrived(self, lane: Lane, now: float) -> None:
        if lane.phase == 'to_park':
            lane.idle()
        elif lane.phase == 'to_bin':
            self._grip(lane, False, now)
        elif lane.phase == 'lift':
            self._to_bin(lane, now)
        elif lane.phase == 'via':
            if lane.route:  # the next leg of a mirrored pair's detour
                phase, target = lane.route.pop(0)
                self._move(lane, phase, target, self._soon(lane, now), now)
            elif lane.holding:
                self._to_bin(lane, now)
            elif not self._chase(lane, self.items.get(lane.item.id, lane.item), now):
                self._give_up(lane, now, f'item {lane.item.id} got away (after a detour)')
        else:  # at the item? a late start (the arm yielded) leaves it short of the item
            seen = self.items.get(lane.item.id)
            if seen is None:
                return self._give_up(lane, now, f'item {lane.item.id} is no longer on the belt')
            # where the item will be when the grasp takes hold (the gripper call's latency)
            off = sorting.predict(self.cell, seen, now + self.grasp_lead)[:2] \
                - lane.target[:2]
            if np.hypot(*off) <= self.s.grasp_reach:
                self._grip(lane, True, now)
            elif not self._chase(lane, seen, now):
                self._give_up(lane, now, f'item {seen.id} got away ({np.hypot(*off):.3f} m)')

    def _chase(self, lane: Lane, item: sorting.SeenItem, now: float) -> bool:
        mirrored = len(lane.robots) > 1
        # a mirrored pair's move takes one hop more (the replication manager) to both planners
        start = now + self.s.decision_lead + (self.s.pair_lead if mirrored else 0.0)
        arm = self.cell.arm(lane.robot)
        q0 = self.q[lane.robot]
        aim = pairing.pair_aim(self.cell, item, self.s.pair_offset) if mirrored else item
        hit = sorting.intercept(self.cell, arm, q0, aim, start, self.s.pick_z,
                                lambda q, p: self.plan(lane.robot, q, p),
                                lead=self.grasp_lead)
        if hit is not None and len(self.lanes) > 1:
            hit = self._unhindered(lane, aim, hit, now)
        if hit is None:
            return False
        lane.item = item
        if mirrored and not pairing.pair_clear(self.cell, lane.robot, hit.traj,
                                               self.s.pair_margin):
            route = pairing.detour(self.cell, self.plan, lane.robot, q0, hit.target,
                                   self.s.carry_z, self.s.pair_margin)
            if route:  # go round first, then meet the item from there
                self._move(lane, 'via', route[0], start, now)
                lane.route = [('via', p) for p in route[1:]]
                return True
        self._move(lane, 'to_item', hit.target, hit.start, now, hit.traj)
        return True

    def _to_bin(self, lane: Lane, now: float) -> None:
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, self.s.drop_clearance)
        self._move_safely(lane, 'to_bin', drop, self._soon(lane, now), now)

    # --- picking --------------------------------------------------------------------------
    def _pick_next(self, lane: Lane, now: float) -> None:
        arm = self.cell.arm(lane.robot)
        others_busy = any(o.phase != 'idle' for o in self.lanes if o is not lane)
        free = [it for i, it in self.items.items()
                if i not in self.claimed and lane.failures.get(i, 0) < 2]
        if self.s.mode == 'mirrored':  # the leader takes its half; the partner is mirrored
            side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
            free = [it for it in free if np.sign(it.position[1]) == side]
        own = None if self.s.mode == 'single' else True
        order = sorting.order_candidates(self.cell, arm, free, now + self.s.decision_lead,
                                         self.s.pick_z, own, steal=others_busy,
                                         other_cycle=self.s.steal_cycle or None, groups=True)
        if self.s.mode != 'mirrored':  # the shortest cycles first, urgent savable items first
            order = sorting.rank_by_cycle(self.cell, arm, self.q[lane.robot], order,
                                          now + self.s.decision_lead, self.s.pick_z,
                                          self.s.drop_clearance, sharing.URGENT_SLACK, SAVABLE)
        self.notes.ranked(lane.robot, order, now)
        for item in [it for _, it in order[:2]]:
            if not self._chase(lane, item, now):
                self.notes.note(item.id, now, f'{lane.robot} could not meet it (or not yet)')
                continue
            self.notes.note(item.id, now, f'{lane.robot} chased it')
            self.claimed[item.id] = lane.robot
            if self.s.mode == 'mirrored':
                partner = sorting.mirror_partner(self.cell, item, list(self.items.values()))
                if partner is not None:
                    self.claimed[partner.id] = self.cell.follower.name
            return
        lane.next_look = now + LOOK_AGAIN  # each look plans: not at every tick

    # --- after a grip -----------------------------------------------------------------------
    def _gripped(self, lane: Lane, now: float) -> None:
        main = lane.grips[lane.robot]
        for robot, track in lane.grips.items():
            if robot != lane.robot and not track.ok:
                self.log('warn', f'{robot} gripper: {track.message}')
        if lane.phase == 'releasing':
            if lane.item is not None:
                self.claimed.pop(lane.item.id, None)
            if not main.ok:
                self.log('warn', f'{lane.robot}: release failed ({main.message})')
            lane.idle()
        elif not main.ok:
            item = lane.item
            lane.failures[item.id] = lane.failures.get(item.id, 0) + 1
            self.claimed.pop(item.id, None)
            self.log('info', f'{lane.robot}: grasp of item {item.id} failed ({main.message})')
            lane.idle()
        elif self.s.carry_z > self.s.pick_z + 1e-6 and self._would_sweep(lane, now):
            up = np.array([lane.target[0], lane.target[1], self.s.carry_z])
            lane.bin_tries, lane.holding = 0, True
            self._move(lane, 'lift', up, self._soon(lane, now), now)
        else:
            lane.bin_tries, lane.holding = 0, True
            self._to_bin(lane, now)

    def _would_sweep(self, lane: Lane, now: float) -> bool:
        """Return True if the item just grasped would touch an item on the belt on its way.

        Then it is lifted clear first: the move to the bin, planned as the job will offer it
        to the planner (the plan memo keeps it for that request), is checked against every
        other item's predicted position with ``carry_clearance`` to spare
        (:func:`scara_collab.core.sorting.carry_sweeps`; in mirrored mode the follower's
        mirror image too). Checking costs about a millisecond; lifting costs a move.
        """
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls, self.s.drop_clearance)
        try:
            traj = self.plan(lane.robot, self.q[lane.robot], drop)
        except ValueError:
            return True
        others = [it for it in self.items.values() if it.id != lane.item.id]
        spare = self.s.carry_z - self.s.pick_z - self.cell.item_size  # = carry_clearance
        return bool(others) and sorting.carry_sweeps(
            self.cell, traj.p, self._soon(lane, now) + traj.t, others, self.s.pick_z, spare,
            mirrored=len(lane.robots) > 1)

    # --- endings --------------------------------------------------------------------------
    def _give_up(self, lane: Lane, now: float, why: str) -> None:
        self.log('warn', f'{lane.robot}: {why}')
        self.give_ups += 1
        self.last_give_up = f't={now:.2f} s {lane.robot} {lane.phase}: {why}'
        if lane.item is not None:
            self.notes.note(lane.item.id, now, f'{lane.robot} gave it up ({why})')
        phase = lane.phase
        lane.route = []
        if lane.holding and phase in MOVING:  # never put an item down off the bin
            lane.bin_tries += 1
            if lane.bin_tries <= self.s.bin_retries:
                self._to_bin(lane, now)
                return
            self.log('warn', f'{lane.robot}: releasing item {lane.item.id} where it is after '
                     f'{lane.bin_tries} bin moves')
            self._grip(lane, False, now)
            return
        if lane.item is not None:
            self.claimed.pop(lane.item.id, None)
            lane.failures[lane.item.id] = lane.failures.get(lane.item.id, 0) + 1
        lane.idle()
        if phase == 'to_park':  # the park move itself failed: stay idle, do not loop
            return
        self._park(lane, now)

    # --- figures --------------------------------------------------------------------------
    def minutes(self, now: float) -> float:
        """Minutes since the job started (0 before)."""
        return 0.0 if self.start_time is None else max(0.0, now - self.start_time) / 60.0

    def rate(self, now: float) -> float:
        """Items sorted per minute since the job started (:func:`items_per_minute`)."""
        return items_per_minute(self.counts.get('sorted', 0), self.minutes(now) * 60.0)
