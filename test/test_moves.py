"""A move's identity and its states (:mod:`scara_collab.core.moves`), without ROS."""
from hypothesis import given, strategies as st
import pytest

from scara_collab.core import arm_planner, lanes, moves


@given(robot=st.sampled_from(['scara_left', 'scara_right', 'cell_1/scara_left']),
       sec=st.integers(0, 2**31 - 1), nanosec=st.integers(0, 999_999_999))
def test_a_move_id_names_its_robot_and_request_both_ways(robot, sec, nanosec):
    """``<robot>/<request ns>`` reads back to the robot and the stamp's nanoseconds, exactly."""
    request = moves.request_id(sec, nanosec)
    assert request == sec * 10**9 + nanosec
    move = moves.move_id(robot, request)
    assert moves.parse_move_id(move) == (robot, request)
    assert moves.request_of(robot, move) == request and moves.planners_move(robot, move)


def test_a_hold_or_a_raw_command_is_no_request():
    """A planner's hold is its own but asks nothing; another arm's or a raw id is not its."""
    with pytest.raises(moves.MoveIdError, match='not <robot>/<request ns>'):
        moves.parse_move_id('scara_left/hold')
    with pytest.raises(ValueError):
        moves.parse_move_id('')
    assert moves.planners_move('scara_right', moves.hold_id('scara_right'))
    assert moves.request_of('scara_right', moves.hold_id('scara_right')) is None
    assert not moves.planners_move('scara_right', 'scara_left/15')
    assert moves.request_of('scara_right', 'scara_left/15') is None
    assert not moves.planners_move('scara_right', 'raw')


def test_the_planners_states_are_spelled_once():
    """The planner's core and the job's lanes take the planner's states from here."""
    assert arm_planner.STATES is moves.PLANNER_STATES
    assert tuple(lanes.PLANNER_STATUS) == moves.PLANNER_STATES
    assert not set(moves.PLANNER_STATES) - set(lanes.MOVE_STATES) - {'refused', 'superseded'}
