"""The belt's parts alone (sim/conveyor.py): the feed's timing, the ends of a line's section."""
from types import SimpleNamespace

import pytest

from scara_collab.core.line import Handoff
from scara_collab.sim.conveyor import Feed, INLET_GAP, SectionEnds


def test_the_feed_comes_once_a_period_and_restarts_from_a_change():
    """Items are due on the period's grid; a change starts the period over; 0 is no feed."""
    feed = Feed(1.5, 'random', now=0.0)
    assert [t for t in (1.0, 1.5, 2.0, 3.0, 3.1) if feed.due(t)] == [1.5, 3.0]
    feed.set(0.0, None, now=3.2)
    assert not feed.due(100.0)
    feed.set(0.5, 'mirror_pairs', now=10.0)
    assert feed.period == 1.0 and not feed.due(10.9) and feed.due(11.0)
    with pytest.raises(ValueError, match='feed interval'):
        feed.set(float('nan'), None, 0.0)
    with pytest.raises(ValueError, match='feed pattern'):
        feed.set(None, 'zigzag', 0.0)


def test_handed_items_arrive_in_order_once_and_bad_ones_are_refused(cell):
    """Arrivals come by time then id, once; an unknown class, y or a repeated id is refused."""
    ends = SectionEnds(SimpleNamespace(cell=cell))  # its bookkeeping alone, with no belt
    red = cell.item_classes[0]
    ends.expect(Handoff(9, red, 0.0, 4.0), at=5.0, known=lambda item: False)
    ends.expect(Handoff(3, red, 0.1, 4.0), at=5.0, known=lambda item: False)
    ends.expect(Handoff(4, red, -0.1, 3.0), at=4.0, known=lambda item: False)
    none = list
    assert ends.arrivals(3.99, none) == []
    x0, speed, half = cell.belt.x_start, cell.belt.speed, cell.item_size / 2
    came = ends.arrivals(5.0, none)  # 4 rode 1 s; 9 would come on into 3: it waits
    assert [(h.item, x) for h, x in came] == [(4, pytest.approx(x0 + speed)), (3, x0)]
    later = 1.0  # s: item 3 has moved on, 9 comes on right behind it
    x3 = x0 + speed * later
    item3 = ((x3 - half, 0.1 - half, 0.2), (x3 + half, 0.1 + half, 0.3))
    came = ends.arrivals(5.0 + later, lambda: [item3])
    assert [(h.item, x) for h, x in came] == [
        (9, pytest.approx(x0 + speed * later - 2 * half - INLET_GAP))]
    assert ends.arrivals(7.0, none) == []
    with pytest.raises(ValueError, match='unknown class'):
        ends.expect(Handoff(5, 'purple', 0.0, 1.0), 2.0, lambda item: False)
    with pytest.raises(ValueError, match='off the belt'):
        ends.expect(Handoff(5, red, cell.belt.centre_y + cell.belt.width, 1.0), 2.0,
                    lambda item: False)
    with pytest.raises(ValueError, match='already on this belt'):
        ends.expect(Handoff(5, red, 0.0, 1.0), 2.0, lambda item: item == 5)
    ends.handed.append(Handoff(1, red, 0.0, 7.0))
    assert [h.item for h in ends.pop_handoffs()] == [1] and ends.pop_handoffs() == []


def test_an_item_past_the_end_is_missed_alone_and_handed_on_in_a_line(cell):
    """Alone the end misses; joined with a cell downstream it hands on, at the crossing time."""
    numbered = []
    ends = SectionEnds(SimpleNamespace(cell=cell, number_from=numbered.append))
    red, belt = cell.item_classes[0], cell.belt
    item = SimpleNamespace(id=4, cls=red)
    assert ends.crossed(item, belt.x_end + 0.1, 0.2, now=10.0) == 'missed'
    assert ends.pop_handoffs() == []
    ends.join(True, first_id=1_000_001)
    assert numbered == [1_000_001]
    assert ends.crossed(item, belt.x_end + 0.1, 0.2, now=10.0) == 'handed_on'
    assert ends.pop_handoffs() == [Handoff(4, red, 0.2, pytest.approx(10.0 - 0.1 / belt.speed))]
