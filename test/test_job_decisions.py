"""The sorting job's decisions (core/job_decisions.py): picking, giving up, the notes kept."""
from test_job import first_pick, item_on_belt, make_job, moves

from scara_collab.core.job_decisions import ItemNotes, LOOK_AGAIN, PICKING


def test_an_arm_with_nothing_to_take_looks_again_later(cell):
    """An idle lane that finds no item waits ``LOOK_AGAIN`` before it plans again."""
    job = make_job(cell)
    lane = job.lane(cell.leader.name)
    assert job.decisions.pick(lane, job.lanes, job.board, 3.0) == []
    assert lane.phase == 'idle' and lane.next_look == 3.0 + LOOK_AGAIN


def test_a_pick_claims_the_item_and_notes_why(cell):
    """The arm that chases an item claims it; the note says so."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    assert job.board.claimed == {1: pick.robot}
    assert job.decisions.notes.close(1).startswith(f'{pick.robot} chased it at t=0.00 s')


def test_giving_up_an_item_frees_it_and_parks_the_arm(cell):
    """A give-up counts, frees the claim, remembers the failure and parks the arm."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    lane = job.lane(pick.robot)
    out = job.decisions.give_up(lane, job.board, 2.0, 'test')
    decisions = job.decisions
    assert decisions.give_ups == 1
    assert decisions.last_give_up.startswith(f't=2.00 s {pick.robot} to_item')
    assert job.board.claimed == {} and lane.failures == {1: 1}
    assert lane.phase == 'to_park' and [m.purpose for m in moves(out)] == ['to_park']
    assert ('warn', f'{pick.robot}: test') in job.logs


def test_giving_up_while_holding_carries_the_item_to_its_bin_again(cell):
    """A lane holding an item never puts it down off the bin: it asks the bin move again."""
    job = make_job(cell)
    pick = first_pick(cell, job)
    lane = job.lane(pick.robot)
    lane.holding, lane.phase = True, 'to_bin'
    out = job.decisions.give_up(lane, job.board, 2.0, 'bin move lost')
    assert lane.bin_tries == 1 and [m.purpose for m in moves(out)] == ['to_bin']
    assert job.board.claimed == {1: pick.robot}  # still its item


def test_each_mode_picks_its_own_way():
    """Mirrored pairs take their half and are not ranked by cycle; the others are."""
    assert PICKING['mirrored'].half and not PICKING['mirrored'].by_cycle
    assert PICKING['collaborative'].own and PICKING['single'].own is None


def test_item_notes_keep_the_last_word_until_the_item_leaves(cell):
    """The last note of an item is returned once, when it leaves the belt."""
    notes = ItemNotes()
    notes.note(4, 1.0, 'a')
    notes.ranked('scara_left', [(0, item_on_belt(cell, item_id=4))], 2.0)
    assert notes.close(4) == 'scara_left ranked it #1 of 1 at t=2.00 s'
    assert notes.close(4) == 'never a candidate of either arm'
