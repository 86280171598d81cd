"""What the sorting job decides: which item an idle arm takes, and what follows each event.

:class:`LaneDecisions` is the job's judgement, apart from its bookkeeping
(:class:`scara_collab.core.job.SortingJob` takes the observations and runs the clock). Each
decision returns the commands it decides, in the order they are to be sent:

- an idle lane picks its next item (:meth:`LaneDecisions.pick`, ranked by
  :func:`scara_collab.core.sorting.rank_by_cycle` as the mode's :class:`Picking` says);
- a lane event (:class:`scara_collab.core.lanes.LaneEvent`) is followed by the next step:
  after a move, grasp, lift, carry, release or chase again (:meth:`LaneDecisions.arrived`);
  after a grip, carry or try another item (:meth:`LaneDecisions.gripped`); after a failure,
  give up, park, or carry a held item to its bin again (:meth:`LaneDecisions.give_up`);
- an arm that waits for the other is unblocked as the belt sharing says
  (:meth:`LaneDecisions.clear_way`).

What it decides about is handed to it: the lanes and the events of the tick, and the belt's
items and claims (:class:`ItemBoard`), one value the job keeps. The moves are made by
:class:`scara_collab.core.job_moves.JobMoves`. No ROS here.
"""
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import line, sharing, sorting
from scara_collab.core.job_moves import JobMoves
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.lanes import Command, Lane, LaneEvent, LaneProtocol, MOVING, Phase
from scara_collab.core.model import CellModel
from scara_collab.core.sharing import Unblock

#: s an idle arm that found nothing to take waits before it looks again (the items move 2 cm)
LOOK_AGAIN = 0.1
#: s it waits when a person kept it from the items it looked at (the person moves slowly)
PERSON_LOOK = 0.5
#: urgent items an arm can still save by taking them first, most urgent first; with more, the
#: feed is faster than the arm and it takes the item that makes the shortest cycle
SAVABLE = 2


@dataclass(frozen=True)
class Picking:
    """How a mode chooses an arm's next item.

    ``own``: prefer items on the arm's half of the belt (None: the whole belt is its own);
    ``half``: take only items on the arm's half, and claim each one's mirror partner for the
    follower (mirrored pairs); ``by_cycle``: rank the candidates by cycle
    (:func:`scara_collab.core.sorting.rank_by_cycle`), else by urgency alone.
    """

    own: Optional[bool]
    half: bool
    by_cycle: bool


#: each mode's :class:`Picking`
PICKING = {'single': Picking(own=None, half=False, by_cycle=True),
           'collaborative': Picking(own=True, half=False, by_cycle=True),
           'mirrored': Picking(own=True, half=True, by_cycle=False)}


@dataclass
class ItemBoard:
    """The belt as the job knows it: the items resting on it now and the arm claiming each.

    :ivar items: the items seen resting on the belt at the last look, by id.
    :ivar claimed: the arm each claimed item is claimed by, by item id.
    """

    items: Dict[int, sorting.SeenItem] = field(default_factory=dict)
    claimed: Dict[int, str] = field(default_factory=dict)


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


class LaneDecisions:
    """The job's decisions for its lanes (see the module docstring).

    :param protocol: the lanes' requests (the arms' joints, the start rule, the grippers'
        measured lead);
    :param moves: the moves the decisions make;
    :param share: in a line of cells, the items this cell leaves downstream (or None);
    :param log: ``log(level, text)``.
    """

    def __init__(self, cell: CellModel, settings: JobSettings, protocol: LaneProtocol,
                 moves: JobMoves, share: Optional[line.Share],
                 log: Callable[[str, str], None]):
        """No give-up yet."""
        self.cell, self.settings, self.protocol, self.moves = cell, settings, protocol, moves
        self.share, self.log = share, log
        self.picking = PICKING[settings.mode]
        #: the job's last word on each item on the belt
        self.notes = ItemNotes()
        self.give_ups = 0
        self.last_give_up = ''

    def next_steps(self, lanes: Sequence[Lane], events: Dict[int, Optional[LaneEvent]],
                   board: ItemBoard, now: float, picking: bool,
                   unused: Sequence[str] = ()) -> List[Command]:
        """Return what every lane does next at ``now`` (sim s), in order.

        The arms no lane uses (``unused``) park first. Then each lane in turn: one that was
        idle picks its next item (if ``picking``, once its look is due); one whose wait ended
        (``events[k]`` for ``lanes[k]``, None while it waits) takes its next step; one still
        waiting for a meeting a person has since come near gives it up
        (:meth:`~scara_collab.core.job_moves.JobMoves.person_in_way`). Last, an
        arm that waits for the other has its way cleared, as the belt sharing says.
        """
        out: List[Command] = list(self.moves.park_unused(list(unused), now))
        for k, lane in enumerate(lanes):
            if k not in events:  # idle
                if picking and now >= lane.next_look:
                    out += self.pick(lane, lanes, board, now)
            elif events[k] is not None:
                out += self.decide(events[k], lanes, board, now)
            elif self.moves.person_in_way(lane, now):
                out += self.give_up(lane, board, now, 'a person came near the meeting before '
                                    'the move began')
        return out + self.clear_way(self.moves.belt.blocked(lanes, now, self.protocol.q),
                                    board, now)

    def decide(self, event: LaneEvent, lanes: Sequence[Lane], board: ItemBoard,
               now: float) -> List[Command]:
        """Return the next step of the lane whose wait ``event`` ended."""
        if event.kind == 'arrived':
            return self.arrived(event.lane, board, now)
        if event.kind == 'gripped':
            return self.gripped(event.lane, board, now)
        why = event.why
        if event.waited:  # never planned: what the other lanes were doing meanwhile
            others = ', '.join(f'{o.robot} {o.phase}' + (' holding' if o.holding else '')
                               for o in lanes if o is not event.lane)
            why += f' ({event.waited}' + (f'; {others})' if others else ')')
        return self.give_up(event.lane, board, now, why)

    # --- after a move -----------------------------------------------------------------------
    def arrived(self, lane: Lane, board: ItemBoard, now: float) -> List[Command]:
        """Go on after every arm of ``lane`` arrived: grasp, lift, carry, release or chase."""
        if lane.phase == Phase.TO_PARK:
            self.moves.free(lane)
            return []
        if lane.phase == Phase.TO_BIN:
            return self.moves.call_grippers(lane, False, now)
        if lane.phase == Phase.LIFT:
            return self.moves.to_bin(lane, now)
        if lane.phase == Phase.VIA:
            if lane.route:  # the next leg of a detour
                phase, target = lane.route.pop(0)
                return [self.moves.go(lane, phase, target,
                                      self.protocol.time.asap(now, lane.mirrored), now)]
            if lane.holding:
                return self.moves.to_bin(lane, now)
            out = self.moves.meet(lane, board.items.get(lane.item.id, lane.item), now)
            return out or self.give_up(lane, board, now,
                                       f'item {lane.item.id} got away (after a detour)')
        # at the item? a late start (the arm yielded) leaves it short of the item
        seen = board.items.get(lane.item.id)
        if seen is None:
            return self.give_up(lane, board, now, f'item {lane.item.id} is no longer on the belt')
        # where the item will be when the grasp takes hold (the gripper call's latency)
        off = sorting.predict(self.cell, seen, now + self.protocol.grips.lead)[:2] \
            - lane.target[:2]
        if np.hypot(*off) <= self.settings.grasp_reach:
            return self.moves.call_grippers(lane, True, now)
        return self.moves.meet(lane, seen, now) or self.give_up(
            lane, board, now, f'item {seen.id} got away ({np.hypot(*off):.3f} m)')

    # --- picking --------------------------------------------------------------------------
    def pick(self, lane: Lane, lanes: Sequence[Lane], board: ItemBoard,
             now: float) -> List[Command]:
        """Send the idle ``lane`` after the best item it can meet, or look again later."""
        s, how = self.settings, self.picking
        arm = self.cell.arm(lane.robot)
        others_busy = any(o.phase != Phase.IDLE for o in lanes if o is not lane)
        free = [it for i, it in board.items.items()
                if i not in board.claimed and lane.failures.get(i, 0) < 2
                and (self.share is None or self.share.takes(i, now))]
        if how.half:  # the leader takes its half; the partner is mirrored
            side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
            free = [it for it in free if np.sign(it.position[1]) == side]
        start = self.protocol.time.decided(now)
        order = sorting.order_candidates(self.cell, arm, free, start,
                                         s.pick_z, how.own, steal=others_busy,
                                         other_cycle=s.steal_cycle or None, groups=True)
        if how.by_cycle:  # the shortest cycles first, urgent savable items first
            order = sorting.rank_by_cycle(self.cell, arm, self.protocol.q[lane.robot], order,
                                          start, s.pick_z,
                                          s.drop_clearance, sharing.URGENT_SLACK, SAVABLE)
        self.notes.ranked(lane.robot, order, now)
        for item in [it for _, it in order[:2]]:
            out = self.moves.meet(lane, item, now)
            if not out:
                self.notes.note(item.id, now, f'{lane.robot} kept clear of a person' if
                                self.moves.declined == 'person'
                                else f'{lane.robot} could not meet it (or not yet)')
                continue
            self.notes.note(item.id, now, f'{lane.robot} chased it')
            board.claimed[item.id] = lane.robot
            if how.half:
                partner = sorting.mirror_partner(self.cell, item, list(board.items.values()))
                if partner is not None:
                    board.claimed[partner.id] = self.cell.follower.name
            return out
        # each look plans: not at every tick; kept clear of a person, less often still
        lane.next_look = now + (PERSON_LOOK if self.moves.declined == 'person' else LOOK_AGAIN)
        if self.moves.declined == 'person':  # every item: then not from next to the person
            return self.moves.away_from_person(lane, now)
        return []

    # --- after a grip -----------------------------------------------------------------------
    def gripped(self, lane: Lane, board: ItemBoard, now: float) -> List[Command]:
        """Go on after every gripper of ``lane`` answered: carry, lift first, or try again.

        An item grasped just as a person came near its bin is let go where it was grasped, on
        the belt (:meth:`~scara_collab.core.job_moves.JobMoves.bin_kept`): it goes on to the
        other arm, or to this one once the person has left (a failed try: an arm tries an item
        twice at most).
        """
        s = self.settings
        main = lane.grips[lane.robot]
        for robot, track in lane.grips.items():
            if robot != lane.robot and not track.ok:
                self.log('warn', f'{robot} gripper: {track.message}')
        if lane.phase == Phase.RELEASING:
            if lane.item is not None:
                board.claimed.pop(lane.item.id, None)
            if not main.ok:
                self.log('warn', f'{lane.robot}: release failed ({main.message})')
            self.moves.free(lane)
            return []
        if not main.ok:
            item = lane.item
            lane.failures[item.id] = lane.failures.get(item.id, 0) + 1
            board.claimed.pop(item.id, None)
            self.log('info', f'{lane.robot}: grasp of item {item.id} failed ({main.message})')
            self.moves.free(lane)
            return []
        lane.bin_tries, lane.holding = 0, True
        if not lane.mirrored and self.moves.bin_kept(lane):  # let it go on along the belt
            item = lane.item
            lane.failures[item.id] = lane.failures.get(item.id, 0) + 1
            self.notes.note(item.id, now, f'{lane.robot} put it back: a person is by its bin')
            self.log('info', f'{lane.robot}: puts item {item.id} back on the belt: a person '
                     'came near its bin')
            return self.moves.call_grippers(lane, False, now)
        if s.carry_z > s.pick_z + 1e-6 and self.moves.would_sweep(lane, board.items, now):
            up = np.array([lane.target[0], lane.target[1], s.carry_z])
            return [self.moves.go(lane, Phase.LIFT, up,
                                  self.protocol.time.asap(now, lane.mirrored), now)]
        return self.moves.to_bin(lane, now)

    # --- out of the way ---------------------------------------------------------------------
    def clear_way(self, how: Optional[Unblock], board: ItemBoard, now: float) -> List[Command]:
        """Return what the belt sharing asks for an arm that waits for the other (or nothing)."""
        if how is None:
            return []
        lane = how.lane
        if how.action == 'park':
            self.log('info', f'{lane.robot}: parks to clear the way for {how.other.robot}')
            return self.moves.to_park(lane, now)
        if how.action == 'reaim':
            return self.aim_elsewhere(lane, how.other, board, now)
        if how.action == 'give_way':
            return self.give_up(lane, board, now, how.why)
        # back out to the waypoint, then on to the bin
        drop = sorting.drop_point(self.cell, lane.robot, lane.item.cls,
                                  self.settings.drop_clearance)
        self.log('info', f'{lane.robot}: both arms hold items and wait for each other: '
                 f'{lane.robot} backs out to y={how.via[1]:.2f} first')
        lane.route = [(Phase.TO_BIN, drop)]
        return [self.moves.go(lane, Phase.VIA, how.via,
                              self.protocol.time.asap(now, lane.mirrored), now)]

    def aim_elsewhere(self, lane: Lane, other: Lane, board: ItemBoard,
                      now: float) -> List[Command]:
        """Ask again for the item an arm waits to meet, where the belt has carried it by now.

        The planner holds a waiting move until the other arm's next move clears the way (the
        other arm waits at an item or its bin while it grips), then plans the target it has:
        by then the item has moved on. Asking again every ``unblock_after`` keeps the target
        current, so the arm meets the item as soon as the way is clear; the item's deadline
        is the belt's end (the intercept no longer exists: give up).
        """
        seen = board.items.get(lane.item.id)
        if seen is None:  # not seen resting on the belt just now: the move's deadline holds
            return []
        if lane.reaims == 0:
            self.log('info', f'{lane.robot}: waits for {other.robot} ({other.phase}); '
                     f're-aims at item {seen.id} while it waits')
        out = self.moves.meet(lane, seen, now)
        if not out:
            return self.give_up(lane, board, now, f'item {seen.id} got away while '
                                f'{lane.robot} waited for {other.robot}')
        lane.reaims += 1
        return out

    # --- endings --------------------------------------------------------------------------
    def give_up(self, lane: Lane, board: ItemBoard, now: float, why: str) -> List[Command]:
        """End ``lane``'s attempt for ``why``: a held item goes to its bin, else it parks."""
        self.log('warn', f'{lane.robot}: {why}')
        self.give_ups += 1
        self.last_give_up = f't={now:.2f} s {lane.robot} {lane.phase}: {why}'
        if lane.item is not None:
            self.notes.note(lane.item.id, now, f'{lane.robot} gave it up ({why})')
        phase = lane.phase
        lane.route = []
        if lane.holding and phase in MOVING:  # never put an item down off the bin
            lane.bin_tries += 1
            if lane.bin_tries <= self.settings.bin_retries:
                return self.moves.to_bin(lane, now)
            self.log('warn', f'{lane.robot}: releasing item {lane.item.id} where it is after '
                     f'{lane.bin_tries} bin moves')
            return self.moves.call_grippers(lane, False, now)
        if lane.item is not None:
            board.claimed.pop(lane.item.id, None)
            lane.failures[lane.item.id] = lane.failures.get(lane.item.id, 0) + 1
        self.moves.free(lane)
        if phase == Phase.TO_PARK:  # the park move itself failed: stay idle, do not loop
            return []
        return self.moves.to_park(lane, now)
