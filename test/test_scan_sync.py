"""The monitor's decision at a scan instant, on that instant's inputs (nodes/scan_sync.py)."""
import pytest
from test_state_sync import Participant

from scara_collab import graph
from scara_collab.nodes.scan_sync import ScanSync

MS = 1_000_000  # ns
INPUTS = ('safety_joint_states', 'planned_velocity', 'scanner_a', 'scanner_b')


def make(enabled=True):
    """Return a ScanSync at 25 Hz recording each decision's inputs, and its log."""
    decided = []
    sync = ScanSync(lambda: decided.append(dict(sync.seen)), 0.04, enabled)
    sync.lockstep = Participant()
    return sync, decided


def scan(sync, t_ms, inputs=INPUTS):
    """Let ``inputs`` come, stamped at ``t_ms``."""
    for name in inputs:
        sync.on_input(name, t_ms * MS)


def test_the_clock_before_the_scans_of_its_instant_waits_for_them_and_the_answer_with_it():
    """Every input came at 40 ms; at the clock of 80 ms two have not: it waits for both."""
    sync, decided = make()
    scan(sync, 40)
    sync.on_tick(40 * MS)
    assert len(decided) == 1 and sync.lockstep.awaited == []
    scan(sync, 80, INPUTS[:2])
    sync.on_tick(80 * MS)
    assert len(decided) == 1 and sync.lockstep.awaited == [('scan', 2)]
    assert sync.missing(2) == ['scanner_a', 'scanner_b']
    scan(sync, 80, ('scanner_b',))
    assert len(decided) == 1  # one still missing
    scan(sync, 80, ('scanner_a',))
    assert decided[-1] == {name: 2 for name in INPUTS}
    assert sync.lockstep.replies == [('scan', 2)]


def test_between_scan_instants_and_with_every_input_in_it_decides_at_once():
    """Off the scan grid nothing is awaited; at a scan instant whose inputs are in, neither."""
    sync, decided = make()
    scan(sync, 40)
    sync.on_tick(40 * MS)
    sync.on_tick(60 * MS)  # between scans: the scans of 80 ms are not due yet
    scan(sync, 80)
    sync.on_tick(80 * MS)
    assert len(decided) == 3 and sync.lockstep.awaited == []


def test_an_input_silent_at_the_last_instant_is_not_waited_for():
    """A scanner that missed the last instant is the monitor's to judge, not to wait for."""
    sync, decided = make()
    scan(sync, 40)
    scan(sync, 80, INPUTS[:3])  # scanner_b falls silent
    sync.on_tick(80 * MS)
    assert sync.lockstep.awaited == [('scan', 2)]
    sync.on_tick(100 * MS)  # its wait ran out (the lockstep answered): decided late, once
    assert len(decided) == 2 and sync.lockstep.replies == [('scan', 2)]
    assert decided[0]['scanner_b'] == 1  # without it
    scan(sync, 120, INPUTS[:3])
    sync.on_tick(120 * MS)  # not awaited again
    assert len(decided) == 3 and sync.lockstep.awaited == [('scan', 2)]


def test_in_real_time_or_without_a_lockstep_it_never_waits():
    """Real time (enabled false) or a node outside the lockstep: decide on what has come."""
    for sync, decided in (make(enabled=False), make()):
        if sync.enabled:
            sync.lockstep = None
        scan(sync, 40)
        sync.on_tick(80 * MS)
        assert len(decided) == 1
    with pytest.raises(ValueError, match='scan period'):
        ScanSync(lambda: None, 0.0)


def test_the_launcher_turns_it_off_in_real_time():
    """Without the lockstep the clock waits for nobody: the monitor takes scans as they come."""
    assert graph.job_params('collaborative', lockstep=False)['separation_monitor'] == {
        'scan_sync': 'false'}
    assert 'scan_sync' not in graph.job_params('collaborative')['separation_monitor']


def test_the_inputs_named_at_the_start_are_awaited_at_the_first_scan_instant():
    """The bridge's scans of sim time 0 go out before the graph runs: the first instant waits."""
    decided = []
    sync = ScanSync(lambda: decided.append(dict(sync.seen)), 0.04, inputs=INPUTS)
    sync.lockstep = Participant()
    sync.on_tick(20 * MS)  # off the grid
    sync.on_tick(40 * MS)
    assert len(decided) == 1 and sync.lockstep.awaited == [('scan', 1)]
    scan(sync, 40)
    assert decided[-1] == {name: 1 for name in INPUTS}


def test_a_decision_that_fails_still_answers_the_lockstep():
    """The node logs a failed decision; sim time must not wait for it."""
    def fail():
        raise RuntimeError('boom')

    sync = ScanSync(fail, 0.04, inputs=('scanner_a',))
    sync.lockstep = Participant()
    sync.on_tick(40 * MS)
    with pytest.raises(RuntimeError):
        sync.on_input('scanner_a', 40 * MS)
    assert sync.lockstep.replies == [('scan', 1)] and sync.due is None
