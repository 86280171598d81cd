"""The moves the sorting job asks (core/job_moves.py): asked and booked, intercepts, parking."""
import numpy as np
from test_job import item_on_belt, make_job

from scara_collab.core.job import MoveCommand
from scara_collab.core.sorting import drop_point


def test_a_park_move_goes_above_the_first_bin_and_is_booked(cell):
    """``to_park`` asks one move to the first bin's drop point and books it on the belt."""
    job = make_job(cell)
    moves, lane = job.moves, job.lane(cell.follower.name)
    out = moves.to_park(lane, 1.0)
    assert len(out) == 1 and isinstance(out[0], MoveCommand)
    cmd = out[0]
    park = drop_point(cell, lane.robot, cell.item_classes[0], job.settings.drop_clearance)
    assert cmd.robot == lane.robot and cmd.purpose == 'to_park'
    assert np.allclose(cmd.target, park) and cmd.start >= 1.0
    assert lane.phase == 'to_park'
    assert job.belt.committed(lane.robot, 1.0, job.q).end > 1.0  # the other lane sees it


def test_a_chase_meets_an_item_in_reach_and_refuses_one_out_of_reach(cell):
    """``meet`` asks a ``to_item`` move on the item's future path, or nothing."""
    job = make_job(cell)
    moves, lane = job.moves, job.lane(cell.leader.name)
    (cmd,) = moves.meet(lane, item_on_belt(cell, x=1.2, y=-0.2), 0.0)
    assert cmd.purpose == 'to_item' and lane.item.id == 1 and cmd.plan is not None
    assert cmd.start >= job.settings.leads.decision
    assert abs(cmd.target[1] - (-0.2)) < 1e-9 and cmd.target[0] > 1.2  # downstream of x
    beyond = item_on_belt(cell, item_id=2, x=cell.belt.x_end - 0.01, y=0.0)
    assert moves.meet(job.lane(cell.follower.name), beyond, 0.0) == []


def test_unused_arms_are_parked_off_the_belt(cell):
    """In ``single`` mode the follower no lane uses is sent to its first bin once."""
    job = make_job(cell, mode='single')
    out = [c for c in job.tick(0.0) if isinstance(c, MoveCommand)]
    parked = [c for c in out if c.robot == cell.follower.name]
    assert len(parked) == 1
    assert np.allclose(parked[0].target, drop_point(cell, cell.follower.name,
                                                    cell.item_classes[0],
                                                    job.settings.drop_clearance))
    assert not [c for c in job.tick(0.02) if getattr(c, 'robot', '') == cell.follower.name]
