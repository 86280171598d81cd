"""A move's identity and the states it is reported in, from the request to the end of the motion.

Plain Python (no numpy, no ROS): the planner, the bridge, the sorting job and the status
protocol (:mod:`scara_collab.nodes.protocol`) all name moves and spell their states from here.

**Requests.** A move is asked for by a request: a target or a plan of the move whose
``header.stamp`` is the requested start. The request's id is that stamp in integer
nanoseconds (:func:`request_id`), exact, so a requester that follows its moves (the sorting
job) names each request by the start it asks for. A request stamped zero ("start now") gets
its receipt time from the planner instead (:class:`scara_collab.core.arm_planner.Answers`).

**Moves.** The move ``robot`` makes for a request is ``<robot>/<request>`` (:func:`move_id`);
the move its planner sends to keep the arm where it is, ``<robot>/hold`` (:func:`hold_id`).
The planner puts the id in the ``header.frame_id`` of the trajectory it publishes and the
bridge reports on that id, so every status says which move it is about.

**States.** A planner reports a request as one of :data:`PLANNER_STATES`, the bridge a
trajectory as one of :data:`EXECUTION_STATES` (their meaning:
:class:`~scara_collab.nodes.protocol.PlannerStatus`,
:class:`~scara_collab.nodes.protocol.ExecutionStatus`).

>>> move = move_id('scara_left', request_id(12, 370_000_000))
>>> move, parse_move_id(move), request_of('scara_left', move)
('scara_left/12370000000', ('scara_left', 12370000000), 12370000000)
>>> planners_move('scara_left', hold_id('scara_left')), request_of('scara_left', 'scara_left/hold')
(True, None)
"""
from typing import Optional, Tuple

#: what a planner did with a request: ``planned`` (the move is sent), ``queued`` (behind the
#: arm's running move), ``waiting`` (the other arm blocks it), ``refused``, ``superseded``
#: (a newer request replaced it before it was planned)
PLANNER_STATES = ('planned', 'queued', 'waiting', 'refused', 'superseded')

#: what the bridge does with a trajectory: ``accepted`` (it runs), ``refused``, ``finished``,
#: ``preempted`` (a newer trajectory replaced it), ``held`` (a stop holds the arm), ``cleared``
#: (the stop is released)
EXECUTION_STATES = ('accepted', 'refused', 'finished', 'preempted', 'held', 'cleared')


class MoveIdError(ValueError):
    """A move id is not ``<robot>/<request ns>``; the text says what it is."""


def request_id(sec: int, nanosec: int) -> int:
    """Return the id of a request stamped ``sec`` s and ``nanosec`` ns: the stamp in ns.

    :param sec: the stamp's whole seconds (``builtin_interfaces/Time.sec``).
    :param nanosec: its nanoseconds (``Time.nanosec``), 0 to 999,999,999.

    >>> request_id(3, 250_000_000), request_id(0, 0)
    (3250000000, 0)
    """
    return int(sec) * 1_000_000_000 + int(nanosec)


def move_id(robot: str, request: int) -> str:
    """Return the id of the move ``robot`` makes for ``request`` (ns): ``'<robot>/<request>'``.

    >>> move_id('scara_left', 1500000000)
    'scara_left/1500000000'
    """
    return f'{robot}/{int(request)}'


def hold_id(robot: str) -> str:
    """Return the id of the hold a planner sends to keep ``robot`` where it is.

    >>> hold_id('scara_right')
    'scara_right/hold'
    """
    return f'{robot}/hold'


def parse_move_id(move: str) -> Tuple[str, int]:
    """Return the robot and the request of a move id (the inverse of :func:`move_id`).

    :raises MoveIdError: if ``move`` is not ``<robot>/<integer>`` (a hold, a raw command).

    >>> parse_move_id('scara_left/15')
    ('scara_left', 15)
    >>> parse_move_id('scara_left/hold')
    Traceback (most recent call last):
    ...
    scara_collab.core.moves.MoveIdError: move id 'scara_left/hold' is not <robot>/<request ns>
    """
    robot, _, request = move.rpartition('/')
    try:
        return robot, int(request)
    except ValueError:
        raise MoveIdError(f'move id {move!r} is not <robot>/<request ns>') from None


def planners_move(robot: str, move: str) -> bool:
    """Return True if ``move`` is one of ``robot``'s planner's (a move of a request, its hold).

    >>> planners_move('scara_left', 'scara_left/15'), planners_move('scara_left', 'raw/1')
    (True, False)
    >>> planners_move('scara_left', 'scara_left/hold'), planners_move('scara_left', '')
    (True, False)
    """
    if move == hold_id(robot):
        return True
    try:
        return parse_move_id(move)[0] == robot
    except MoveIdError:
        return False


def request_of(robot: str, move: str) -> Optional[int]:
    """Return the request of ``robot``'s move ``move``, or None for any other move.

    >>> request_of('scara_left', 'scara_left/15'), request_of('scara_left', 'scara_left/hold')
    (15, None)
    >>> request_of('scara_left', 'scara_right/15') is None
    True
    """
    try:
        _, request = parse_move_id(move)
    except MoveIdError:
        return None  # a planner's hold, a raw command
    return request if move_id(robot, request) == move else None
