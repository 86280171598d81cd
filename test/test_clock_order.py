"""ClockOrder: what the bridge published at a clock instant reaches the tick in clock order."""
from scara_collab.nodes.clock_order import ClockOrder


def _run(arrivals):
    """Feed ``arrivals`` (('clock', t) or ('state', t)); return what each tick saw."""
    order, seen, ticks = ClockOrder(), [], []
    for kind, t in arrivals:
        if kind == 'clock':
            ticks.append((t, seen[-1] if seen else None))  # the tick runs first
            order.advance(t)
        else:
            order.admit(t, lambda t=t: seen.append(t))
    return ticks, seen


def test_a_state_ahead_of_its_clock_reaches_the_tick_as_if_it_came_after():
    """Clock, state, half-way state per 20 ms window; then the same with states overtaking."""
    normal, overtaken = [], []
    for k in range(1, 8):
        t = 0.02 * k
        normal += [('clock', t), ('state', t), ('state', t + 0.01)]
        ahead = k > 2 and k % 2  # once the clock's step is known (two clocks)
        overtaken += [('state', t), ('clock', t)] if ahead else [('clock', t), ('state', t)]
        overtaken += [('state', t + 0.01)]
    assert _run(overtaken) == _run(normal)
    ticks, seen = _run(normal)
    assert ticks[3] == (0.08, 0.02 * 3 + 0.01)  # the tick at t saw the half-way state before t


def test_nothing_is_held_before_the_clock_has_a_step():
    """Before two clocks the step is unknown: everything is handed on at once."""
    order, seen = ClockOrder(), []
    order.admit(5.0, lambda: seen.append(5.0))
    order.advance(0.02)
    order.admit(7.0, lambda: seen.append(7.0))
    assert seen == [5.0, 7.0] and not order.held
