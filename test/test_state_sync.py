"""A tick at T decided on the joint state of T (nodes/state_sync.py), with a stand-in lockstep."""
from scara_collab.nodes.state_sync import StateSync


class Participant:
    """A lockstep participant that records what it is asked to wait for and what came."""

    def __init__(self):
        """Nothing awaited."""
        self.awaited, self.replies = [], []

    def await_reply(self, key):
        """Record a wait."""
        self.awaited.append(key)

    def reply(self, key):
        """Record a reply."""
        self.replies.append(key)


def make(enabled=True):
    """Return a StateSync at 100 Hz states recording each decision's state time, and its log."""
    decided = []
    sync = StateSync(lambda: decided.append(sync.state_time), 0.01, enabled)
    sync.lockstep = Participant()
    return sync, decided


def test_a_tick_waits_for_the_state_of_its_instant_and_the_answer_with_it():
    """The state of T - 10 ms is in at the clock of T: the tick waits for the state of T."""
    sync, decided = make()
    sync.on_state(0.99)
    sync.on_tick(1.0)
    assert decided == [] and sync.lockstep.awaited == [('state', 1.0)]
    sync.on_state(1.0)
    assert decided == [1.0] and sync.lockstep.replies == [('state', 1.0)]
    sync.on_state(1.01)  # a later state decides nothing
    assert decided == [1.0]


def test_a_tick_whose_state_is_in_decides_at_once():
    """The state of T came before the clock of T: no wait."""
    sync, decided = make()
    sync.on_state(1.0)
    sync.on_tick(1.0)
    assert decided == [1.0] and sync.lockstep.awaited == []


def test_without_states_or_in_real_time_the_tick_never_waits():
    """No state yet, states that stopped coming, or real time: decide on what is there."""
    sync, decided = make()
    sync.on_tick(0.02)  # none yet
    sync.on_state(0.5)
    sync.on_tick(1.0)  # the last one is 0.5 s old: the states stopped
    assert decided == [float('-inf'), 0.5] and sync.lockstep.awaited == []
    rt, decided = make(enabled=False)
    rt.on_state(0.99)
    rt.on_tick(1.0)
    assert decided == [0.99] and rt.lockstep.awaited == []


def test_a_state_that_never_comes_is_decided_without_at_the_next_tick():
    """A lost state: the next tick first decides the one that waited, on the newest state."""
    sync, decided = make()
    sync.on_state(0.99)
    sync.on_tick(1.0)
    sync.on_tick(1.02)  # the state of 1.0 was lost; the one of 1.01 never came either
    assert decided == [0.99, 0.99] and sync.lockstep.replies == [('state', 1.0)]
