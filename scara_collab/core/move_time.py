"""When a move starts: the one rule, from the job's decision to the bridge's execution.

A move's start is decided hop by hop, each hop by a rule written here once:

==========================  =====================================  ===========================
who, when                   rule                                   start
==========================  =====================================  ===========================
the job decides to meet an  :meth:`MoveTime.decided`               ``now + decision`` (a
item                                                               mirrored pair: ``+ pair``)
the job asks the next move  :meth:`MoveTime.asap`                  ``now + move`` (a pair:
as soon as possible                                                ``pair``) ``+`` typical
                                                                   lateness
the job names the request   :meth:`MoveTime.requested`             at least 1 ms after ``now``
a planner takes a request   :meth:`MoveTime.wanted`                its stamp, or (stamped 0)
                                                                   ``now + planning +`` worst
                                                                   lateness
a planner sends the move    :meth:`MoveTime.sendable`              no sooner than ``now + send
                                                                   +`` worst lateness
the stamp it carries        :func:`stamp_time`                     whole nanoseconds
the bridge runs it          :func:`start_time`                     its stamp; stamped 0 or
                                                                   more than a physics step in
                                                                   the past: ``now`` (late)
==========================  =====================================  ===========================

The leads (:class:`Leads`) come from ``config/automation.yaml``, ``config/controllers.yaml``
and the planners' ``send_margin`` parameter, and only this module reads them. How late the
bridge starts a node's moves is measured in one place (:meth:`MoveTime.started`, with
:func:`lateness`) and added to the leads that depend on it.

Every rule takes the time as an argument (``now``, sim s): a node passes its clock's time, so
a paused, scaled or simulated clock changes what is passed in, never the rule.
"""
from dataclasses import dataclass
from typing import List, Mapping, Optional


class Refused(ValueError):
    """A trajectory the rules do not run; the message says why."""


@dataclass(frozen=True)
class Leads:
    """How far ahead of ``now`` each hop asks a move to start, s.

    :ivar decision: the job, for a move it decides now (``decision_lead``).
    :ivar move: the job, for the next move of one arm as soon as possible: a planner's
        ``planning_lead``, as the planner would start it.
    :ivar pair: the job, for a mirrored pair's move (``mirror_start_lead``): one hop more, via
        the replication manager, so both planners get the same start, still in the future.
    :ivar planning: a planner, for a move asked for now (stamped 0) (``planning_lead``).
    :ivar send: a planner, the least time between sending a move and its start
        (``send_margin``).
    """

    decision: float = 0.1
    move: float = 0.05
    pair: float = 0.1
    planning: float = 0.05
    send: float = 0.05

    @staticmethod
    def of(automation: Optional[Mapping[str, object]] = None,
           controllers: Optional[Mapping[str, object]] = None,
           send_margin: Optional[float] = None) -> 'Leads':
        """Return the leads of the config trees and a planner's ``send_margin`` (default kept).

        >>> Leads.of({'decision_lead': 0.2, 'mirror_start_lead': 0.1}, {'planning_lead': 0.05})
        Leads(decision=0.2, move=0.05, pair=0.1, planning=0.05, send=0.05)
        """
        out = {}
        if automation is not None:
            out.update(decision=float(automation['decision_lead']),
                       pair=float(automation['mirror_start_lead']))
        if controllers is not None:
            out.update(move=float(controllers['planning_lead']),
                       planning=float(controllers['planning_lead']))
        if send_margin is not None:
            out['send'] = float(send_margin)
        return Leads(**out)

    def __post_init__(self):
        """Refuse a lead that is not > 0."""
        for key in ('decision', 'move', 'pair', 'planning', 'send'):
            if not float(getattr(self, key)) > 0.0:
                name = {'planning': 'planning_lead', 'send': 'send_margin'}.get(key, key)
                raise ValueError(f'{name} must be > 0, got {getattr(self, key)!r}')


def lateness(stamp: Optional[float], start: float) -> float:
    """Return how late a move stamped ``stamp`` starts at ``start``, s (0: on time or unstamped).

    >>> lateness(2.0, 2.25), lateness(2.0, 2.0), lateness(0.0, 5.0), lateness(None, 5.0)
    (0.25, 0.0, 0.0, 0.0)
    """
    return max(0.0, start - stamp) if stamp else 0.0


def start_time(stamp: float, duration: float, now: float, dt: float) -> float:
    """Return when a trajectory stamped ``stamp`` and ``duration`` long starts, at ``now``.

    The bridge's rule, as ros2_control's joint trajectory controller has it: stamp 0 is now;
    a stamp more than one physics step ``dt`` in the past is now (late).

    >>> start_time(0.0, 2.0, now=5.0, dt=0.001), start_time(6.0, 2.0, 5.0, 0.001)
    (5.0, 6.0)
    >>> start_time(4.5, 2.0, 5.0, 0.001)   # late: starts now
    5.0

    :raises Refused: it would have ended before ``now``.
    """
    start = now if stamp == 0.0 else float(stamp)
    if start + duration < now:
        raise Refused(f'it ended {now - start - duration:.3f} s ago')
    return now if start < now - dt else start


def stamp_time(t: float) -> float:
    """Return the time a message stamp says for ``t``: what the bridge reads back.

    A stamp (``builtin_interfaces/Time``) holds whole nanoseconds; read back as
    ``sec + nanosec * 1e-9`` (``nodes.conversions.to_time``, ``to_sec``). A planner that
    decides by a start must decide by this one, the start the door will see: a sim clock at
    190.70000000000002 s plus 0.05 s is 190.75000000000003, but the stamp says 190.75, and the
    priority rule tells those apart.

    >>> 190.70000000000002 + 0.05, stamp_time(190.70000000000002 + 0.05)
    (190.75000000000003, 190.75)
    """
    ns = int(round(float(t) * 1e9))
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


class Lateness:
    """How late things have come lately: the largest of the last ``window`` samples, s.

    A node that must act ahead of time (a planner's lead before a move's start, the monitor's
    latency before a stop takes hold) adds what it measures instead of assuming lockstep's
    timing; on-time samples (0) let it fall back as the late ones leave the window.

    >>> late = Lateness(window=3)
    >>> for s in (0.0, 0.25, 0.0, 0.0):
    ...     late.add(s)
    >>> late.worst, late.typical, (late.add(0.0), late.worst)[1]
    (0.25, 0.0, 0.0)

    :param window: samples kept; :param cap: s, the most it ever says (a stall is not latency).
    """

    def __init__(self, window: int = 20, cap: float = 1.0):
        """Nothing measured yet: 0 s."""
        self.window, self.cap = int(window), float(cap)
        self._samples: List[float] = []

    def add(self, seconds: float) -> None:
        """Take one measured delay, s (negative counts as 0)."""
        self._samples.append(min(max(float(seconds), 0.0), self.cap))
        if len(self._samples) > self.window:
            del self._samples[0]

    @property
    def worst(self) -> float:
        """The largest delay in the window, s (to wait for: a timeout)."""
        return max(self._samples, default=0.0)

    @property
    def typical(self) -> float:
        """The median delay in the window, s (to aim with: a one-off spike does not count)."""
        if not self._samples:
            return 0.0
        ordered = sorted(self._samples)
        return ordered[(len(ordered) - 1) // 2]


class MoveTime:
    """One node's use of the start rule: its leads and how late the bridge started its moves.

    The job and each planner keep one (they run in processes of their own); each asks it for
    every start it decides and tells it every start the bridge reports.

    >>> clock = MoveTime(Leads(decision=0.1, move=0.05))
    >>> clock.decided(2.0), clock.asap(2.0)
    (2.1, 2.05)
    >>> clock.started(stamp=2.0, start=2.25); clock.wanted(0.0, 3.0)   # 3.0 + 0.05 + 0.25
    3.3

    :param leads: the leads (:class:`Leads`); a planner's may change while it runs.
    """

    def __init__(self, leads: Leads):
        """Nothing measured yet."""
        self.leads = leads
        #: how late the bridge started this node's stamped moves, s
        self.late = Lateness()

    def started(self, stamp: Optional[float], start: float) -> None:
        """Take the start the bridge reports for a move stamped ``stamp`` (:func:`lateness`)."""
        self.late.add(lateness(stamp, start))

    # --- the job --------------------------------------------------------------------------
    def decided(self, now: float, mirrored: bool = False) -> float:
        """Return the start of a move the job decides at ``now`` (a mirrored pair's if asked)."""
        return now + self.leads.decision + (self.leads.pair if mirrored else 0.0)

    def asap(self, now: float, mirrored: bool = False) -> float:
        """Return the start to ask at ``now`` for a move that should start as soon as possible.

        One arm: a planner's planning lead ahead: the time the request, the planning and the
        trajectory's way to the bridge may take. Asked for that start, a planner keeps it
        while it can still send the move in time, so the time the job took to decide counts
        into the lead instead of coming on top of it. A mirrored pair: the pair's lead, so
        both planners get a start that is still in the future and plan the same. Either way
        the typical lateness measured (0 in lockstep) comes on top, so the start the job plans
        with is the one the move gets.
        """
        lead = self.leads.pair if mirrored else self.leads.move
        return now + lead + self.late.typical

    @staticmethod
    def requested(start: float, now: float) -> float:
        """Return the start a request names: ``start``, at least a millisecond after ``now``."""
        return max(start, now + 1e-3)

    # --- a planner ------------------------------------------------------------------------
    def wanted(self, stamp: float, now: float) -> float:
        """Return the start wanted for a request stamped ``stamp`` (0: as soon as possible).

        A start asked for is kept; one asked for now gets the planning lead from ``now`` (its
        receipt), plus the worst lateness measured.
        """
        return stamp if stamp > 0 else now + self.leads.planning + self.late.worst

    def sendable(self, start: float, now: float) -> float:
        """Return ``start``, or the earliest start a move sent at ``now`` can still make."""
        return max(start, now + self.leads.send + self.late.worst)

    def ahead(self, start: float, now: float) -> bool:
        """Return True if a move starting at ``start`` has surely not started by ``now``.

        Its start is further off than the worst lateness measured lately.
        """
        return start > now + self.late.worst
