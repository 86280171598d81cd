"""The sorting job as a state machine, without ROS: observations in, commands out.

:class:`SortingJob` decides everything the automation manager does; the node only turns
messages into the ``on_*`` observations, calls :meth:`SortingJob.tick` on a timer and turns
the returned :class:`MoveCommand` / :class:`GripCommand` into messages and service calls.

A *lane* is one arm's work (``single``: the leader; ``collaborative``: one lane per arm;
``mirrored``: one lane that moves both arms, the follower to the mirror image). Its phases
(:class:`~scara_collab.core.lanes.Phase`, from which this table is made):
{phases}

Every observation names what it is about (a move by its request, a grip by its token), so a
late, duplicated or unknown one is ignored, and every waiting phase has a deadline, so a lost
one costs a retry, never the run. The servers are idempotent (a planner re-publishes the status
of a request it already has; a grasp while holding and a release while empty succeed), so a
re-sent request is always safe. Each move goes out with the job's plan of it (the one it
was chosen by), which the planner schedules without planning it again.

The job owns its lanes and what it knows of the belt's items (an
:class:`~scara_collab.core.job_decisions.ItemBoard`), and hands both to its parts, each a plain
object tested alone:

- its request protocol (:class:`scara_collab.core.lanes.LaneProtocol`): it opens the moves
  and grips the job decides on, tracks their answers and deadlines, and reports each lane's
  outcome as a :class:`scara_collab.core.lanes.LaneEvent` (arrived, gripped, failed);
- its belt sharing (:class:`scara_collab.core.sharing.SharedBelt` in ``collaborative`` mode,
  :class:`scara_collab.core.sharing.SoloBelt` otherwise, chosen once): what each arm is
  committed to (the committed-motion model, with the moves the job asked booked in it), a
  chase timed around the other arm, how to unblock two arms that wait for each other, the
  follower's moves held for the leader's answer;
- its decisions (:class:`scara_collab.core.job_decisions.LaneDecisions`): which item an idle
  arm takes and when (ranked by :func:`scara_collab.core.sorting.rank_by_cycle`), what follows
  each event, how an arm that waits for the other is unblocked; each returns its commands;
- its moves (:class:`scara_collab.core.job_moves.JobMoves`), which the decisions make: each
  opened and booked, the intercept of an item, a mirrored pair kept apart
  (:mod:`scara_collab.core.pairing`).

One tick (:meth:`SortingJob.tick`) goes through them in one direction: the protocol follows
every waiting lane to ``now`` (what is sent again, what ended each wait), the decisions
decide on all of it, the belt sharing sends the result in turn.
"""
import dataclasses
import math
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from scara_collab.core import line, sorting, ssm
from scara_collab.core.job_decisions import ItemBoard, LaneDecisions
from scara_collab.core.job_moves import JobMoves
from scara_collab.core.job_settings import JobSettings
from scara_collab.core.lanes import (Command, GripCommand, Lane, LaneEvent, LaneProtocol,
                                     MoveCommand, open_track, Phase, phase_table, PlanFn,
                                     PlanMemo)
from scara_collab.core.model import CellModel
from scara_collab.core.sharing import SharedBelt, SoloBelt

__doc__ = __doc__.format(phases=phase_table())
__all__ = ['GripCommand', 'items_per_minute', 'JobSettings', 'MoveCommand', 'SortingJob']


def items_per_minute(sorted_count: int, seconds: float) -> float:
    """Items sorted per minute over a window of ``seconds`` (0 for an empty window).

    The one definition used by the job's stats, the run summary and the benchmarks: the
    window starts when the feed starts (the job's start) and ends at the run's end.

    >>> items_per_minute(30, 60.0)
    30.0
    """
    return 60.0 * sorted_count / seconds if seconds > 0 else 0.0


class SortingJob:
    """The sorting job's decisions (see the module docstring).

    :param cell: the cell model.
    :param settings: the tuning (:meth:`JobSettings.from_config`).
    :param plan: ``plan(robot, q_start, target) -> Trajectory`` with the planners' settings
        (raises ``ValueError`` if refused): the job times intercepts with the planners' own
        trajectories.
    :param log: ``log(level, text)`` for decisions worth a log line (``'info'``, ``'warn'``).
    """

    def __init__(self, cell: CellModel, settings: JobSettings, plan: PlanFn,
                 log: Callable[[str, str], None] = lambda level, text: None,
                 people: Optional[ssm.SsmParams] = None):
        """Set up one lane per arm that moves on its own (one for a mirrored pair); not started."""
        self.cell, self.settings, self.log = cell, settings, log
        lead, foll = cell.leader, cell.follower
        specs = {'single': [(lead.name, (lead.name,))],
                 'collaborative': [(lead.name, (lead.name,)), (foll.name, (foll.name,))],
                 'mirrored': [(lead.name, (lead.name, foll.name))]}[settings.mode]
        #: the job's plans, each planned once per tick (every part of the job plans with it)
        self.plan = PlanMemo(plan)
        #: the job's lanes: its own, handed to its parts at each call
        self.lanes: List[Lane] = [Lane(r, rs) for r, rs in specs]
        #: the belt's items and their claims, as the job knows them
        self.board = ItemBoard()
        self.protocol = LaneProtocol(cell, settings, self.plan, log)
        self.belt = (SharedBelt if settings.mode == 'collaborative' else SoloBelt)(
            cell, settings, self.plan)
        # a meeting near a person is chosen with room to spare beyond the protective separation
        aside = (None if people is None else
                 dataclasses.replace(people, intrusion=people.intrusion + settings.person_buffer))
        self.moves = JobMoves(cell, settings, self.protocol, self.belt, self.plan, aside)
        #: in a line of cells, the items this cell leaves for the ones downstream
        self.share = (line.Share(settings.line_cell, settings.line_cells, settings.line_capacity)
                      if settings.line_cells > 1 else None)
        self.decisions = LaneDecisions(cell, settings, self.protocol, self.moves, self.share, log)
        used = {r for lane in self.lanes for r in lane.robots}
        self._unused = [a.name for a in cell.arms if a.name not in used]
        self._parked_unused = False
        self.running = False
        self.estop = False
        self.start_time: Optional[float] = None
        self.counts: Dict[str, int] = {}
        self.sorted_by: Dict[str, int] = {a.name: 0 for a in cell.arms}
        #: missed items the person cost: left for a person, or on the belt while an arm was
        #: slowed or stopped for one (:meth:`on_persons`)
        self.missed_due_to_person = 0
        self._seen_at: Dict[int, float] = {}  # item id -> sim s it was first seen on the belt
        self._hindered_at = -math.inf  # sim s an arm was last slowed or stopped for a person

    # --- what it knows --------------------------------------------------------------------
    @property
    def q(self) -> Dict[str, np.ndarray]:
        """The arms' measured joints ``(3,)`` by name (the protocol's, which arrival checks)."""
        return self.protocol.q

    def phases(self) -> Dict[str, str]:
        """Each lane's phase, by its robot."""
        return {lane.robot: str(lane.phase) for lane in self.lanes}

    def lane(self, robot: str) -> Lane:
        """Return the lane that decides for ``robot``.

        :raises StopIteration: no lane does (the follower in ``single`` or ``mirrored`` mode).
        """
        return next(lane for lane in self.lanes if lane.robot == robot)

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
        self.board.items = {it.id: it for it in items}
        for it in items:
            self._seen_at.setdefault(it.id, it.stamp)
        if self.share is not None and self.board.items:
            self.share.see(self.board.items, max(it.stamp for it in items))

    def on_persons(self, persons: Sequence[ssm.Person], hindered: bool = False,
                   now: Optional[float] = None) -> None:
        """Take the persons the separation monitor sees now: meetings are chosen away from them.

        :param hindered: an arm runs slowed or stopped for a person now (the monitor's
            factors): an item missed that was on the belt meanwhile counts as the person's.
        :param now: the monitor's sim time of it (default: the job's).
        """
        self.moves.persons = tuple(persons)
        if hindered:
            self._hindered_at = self.protocol.now if now is None else float(now)

    def on_estop(self, on: bool) -> None:
        """Take the emergency stop: while set, nothing new is commanded."""
        self.estop = bool(on)

    def on_arm_state(self, robot: str, q: np.ndarray) -> None:
        """Take the measured joints of ``robot`` ``(3,)`` (finite, checked by the caller)."""
        self.protocol.measured(robot, q)

    def on_planner(self, robot: str, request: int, state: str, start: Optional[float],
                   end: Optional[float], reason: str = '') -> None:
        """Take a planner status about ``robot``'s move for ``request`` (others are ignored)."""
        track = self.protocol.on_planner(self.lanes, robot, request, state, start, end, reason)
        if track is not None:
            self.belt.answered(robot, track, self._target(robot, request), self.q)

    def on_execution(self, robot: str, request: int, state: str, start: Optional[float],
                     end: Optional[float], reason: str = '',
                     stamp: Optional[float] = None) -> None:
        """Take a bridge execution status about ``robot``'s move for ``request``.

        :param stamp: the start an ``accepted`` move asked for (None or 0: none).
        """
        track = self.protocol.on_execution(self.lanes, robot, request, state, start, end,
                                           reason, stamp)
        if track is not None:
            self.belt.answered(robot, track, self._target(robot, request), self.q)

    def _target(self, robot: str, request: int) -> np.ndarray:
        """Return the target of the lane whose current request of ``robot`` is ``request``."""
        return next(la.target for la in self.lanes if la.request == request and robot in la.moves)

    def on_trajectory(self, robot: str, move_id: str, request: Optional[int], stamp: float,
                      t: np.ndarray, q: np.ndarray) -> None:
        """Take a trajectory ``robot`` was sent: a planner's move of the job's, or any other.

        With two lanes the arm is committed to it (the belt's booking, by the committed-motion
        model's rules; the bridge's statuses correct it: :meth:`on_arm_status`).

        :param move_id: its name; :param request: the job's request it answers, or None (a
            raw command, a hold); :param stamp: its start, s (0: now); :param t: ``(N,)`` s
            from its start; :param q: ``(N, 3)`` joint positions.
        """
        if request is not None and open_track(self.lanes, robot, request) is None:
            request = None  # not an open move of the job's (an old one)
        self.belt.on_trajectory(robot, move_id, request, stamp, t, q, self.protocol.now, self.q)

    def on_clock(self, robot: str, lag: float) -> None:
        """Take ``robot``'s trajectory clock: ``lag`` s behind sim time (speed scaling)."""
        self.protocol.lags[robot] = float(lag)
        self.belt.on_clock(robot, lag)

    def on_arm_status(self, robot: str, state: str, move_id: str,
                      start: Optional[float] = None) -> None:
        """Take the bridge's status of any move of ``robot`` (what the arm is committed to)."""
        self.belt.on_status(robot, state, move_id, start, self.protocol.now, self.q)

    def on_grip(self, token: int, ok: bool, message: str = '') -> None:
        """Take a gripper response for request ``token``: any attempt of a grip still open."""
        self.protocol.grips.on_response(self.lanes, token, ok, message, self.protocol.now)

    def on_item_event(self, kind: str, item: int, robot: str) -> None:
        """Count a bridge item event; it also confirms grasps and releases.

        An item that ``slipped`` from a gripper is no longer its lane's: the lane carries
        nothing on, and the item, wherever it lands, is free for either arm (on the belt it
        is an item like any other).
        """
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind == 'slipped':
            self.board.claimed.pop(item, None)
            self.decisions.notes.note(item, self.protocol.now,
                                      f'it slipped from the {robot} gripper')
            for lane in self.lanes:
                if lane.item is not None and lane.item.id == item:
                    lane.holding = False
        if kind == 'sorted' and robot in self.sorted_by:
            self.sorted_by[robot] += 1
        if kind in sorting.GONE:
            self.board.claimed.pop(item, None)
            last = self.decisions.notes.close(item)
            seen = self._seen_at.pop(item, math.inf)
            if kind == 'missed':
                person = 'clear of a person' in last or self._hindered_at >= seen
                if person and 'clear of a person' not in last:
                    last += '; an arm was slowed or stopped for a person meanwhile'
                self.log('warn', f'item {item} missed; last: {last}')
                self.missed_due_to_person += person
        self.protocol.grips.confirm(self.lanes, kind, robot)

    # --- the clock ------------------------------------------------------------------------
    def tick(self, now: float) -> List[Command]:
        """Advance every lane to ``now`` (sim s); return the commands to send, in order.

        The protocol follows every lane that waits (a move, a grip) to ``now``: what it sends
        again, and the event that ends each wait. The decisions then decide for every lane
        (an idle one picks its next item, one whose wait ended takes its next step) and clear
        the way for an arm that waits for the other. The belt sharing sends the follower's
        moves only once the leader's planner has answered.
        """
        self.protocol.now = now
        self.plan.forget()
        if self.estop or not self.protocol.knows_every_arm():
            self.belt.drop_held()  # nothing new is commanded; a lane re-sends after answer_timeout
            return []
        out: List[Command] = []
        events: Dict[int, Optional[LaneEvent]] = {}
        for k, lane in enumerate(self.lanes):
            if lane.phase != Phase.IDLE:
                sent, events[k] = self.protocol.advance(lane, now)
                out += sent
        unused = self._unused if self.running and not self._parked_unused else ()
        self._parked_unused = self._parked_unused or self.running
        out += self.decisions.next_steps(self.lanes, events, self.board, now, self.running,
                                         unused)
        return self.belt.in_turn(out, self.lanes, now)

    def chase(self, robot: str, item: sorting.SeenItem, now: float) -> List[MoveCommand]:
        """Send ``robot``'s lane after ``item`` now, as a pick would (the item is not claimed).

        :return: the moves asked, in order (the caller sends them); ``[]`` if the arm cannot
            meet the item (or not without waiting for the other arm's booked move).
        """
        return self.moves.meet(self.lane(robot), item, now)

    def park(self, robot: str, now: float) -> List[MoveCommand]:
        """Send ``robot``'s lane to wait clear of the shared zone; return the moves asked."""
        return self.moves.to_park(self.lane(robot), now)

    # --- figures --------------------------------------------------------------------------
    def minutes(self, now: float) -> float:
        """Minutes since the job started (0 before)."""
        return 0.0 if self.start_time is None else max(0.0, now - self.start_time) / 60.0

    def rate(self, now: float) -> float:
        """Items sorted per minute since the job started (:func:`items_per_minute`)."""
        return items_per_minute(self.counts.get('sorted', 0), self.minutes(now) * 60.0)
