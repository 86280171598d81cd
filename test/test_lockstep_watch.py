"""The launcher's lockstep watch keeps every silence: who, from when, how long, dropped or not."""
import pytest

from scara_collab.nodes.lockstep_watch import LOCKSTEP_TIMEOUT, LockstepWatch, NOTICE

END = float(2**31 - 1)  # lockstep.END_OF_TIME: a node that leaves


def run(watch, seconds, answers, sim_rate=1.0, t0=0.0):
    """Drive ``watch`` once a wall second as the launcher does: answers, then a look.

    :param answers: ``answers(name, wall)`` -> the sim time ``name`` has reached, or None
        (silent); sim time runs at ``sim_rate`` from ``t0`` (the bridge's newest /clock).
    """
    for wall in range(1, seconds + 1):
        sim_now = t0 + sim_rate * wall
        for name in sorted(watch.names):
            t = answers(name, wall, sim_now)
            if t is not None:
                watch.answer(name, t, float(wall))
        watch.look(sim_now, float(wall))


def test_healthy_nodes_and_a_stall_are_no_silence():
    """Nodes that answer each look, or sim time that stands still, leave no silence."""
    watch = LockstepWatch(['/a', '/b'], limit=10.0)
    run(watch, 20, lambda name, wall, now: now - 0.02)
    run(watch, 10, lambda name, wall, now: 20.0 - 0.02 if name == '/a' else 19.98,
        sim_rate=0.0, t0=20.0)  # paused: nobody gets a new /clock
    assert watch.silences == []


def test_each_silence_is_named_with_its_length_and_whether_the_bridge_waited():
    """A node that misses looks is named (sim time, wall s); beyond the timeout it is dropped.

    The lockstep holds sim time while one node is silent (0.02 s ahead of it), then the
    bridge drops it and sim time goes on: sim seconds behind grow too.
    """
    watch = LockstepWatch(['/a', '/b', '/c'], limit=30.0)
    gone = {'/b': (10, 14), '/c': (30, 99)}  # wall s of the last answer, of the next one
    t = 0.0
    for wall in range(1, 60):
        silent = [n for n, (lo, hi) in gone.items() if lo < wall < hi]
        if all(wall - gone[n][0] > LOCKSTEP_TIMEOUT for n in silent):
            t += 1.0  # nobody waited for (dropped after the timeout): sim time goes on
        else:
            t = max(watch.reached[n] for n in silent) + 0.02  # the lockstep window
        for name in sorted(watch.names):
            lo, hi = gone.get(name, (0, 0))
            if not lo < wall < hi:
                watch.answer(name, t, float(wall))
        watch.look(t, float(wall))
    b, c = watch.silences
    assert (b.node, b.ended, b.dropped) == ('/b', True, False)
    assert b.sim_time == pytest.approx(10.0) and b.wall_s == pytest.approx(4.0)
    assert (c.node, c.ended, c.dropped) == ('/c', False, True)
    assert c.sim_time == pytest.approx(27.02) and c.wall_s == pytest.approx(29.0)
    assert c.lag_s > 20.0, 'sim time went on without it'
    assert b.values()['node'] == 'b' and set(b.values()) == {
        'node', 'sim_time', 'wall_s', 'lag_s', 'ended', 'dropped'}


def test_a_silence_is_named_only_after_a_whole_look_without_an_answer():
    """One look without an answer (1 s, the watch's resolution) is not yet a silence."""
    watch = LockstepWatch(['/a', '/b'], limit=10.0)
    run(watch, 10, lambda name, wall, now: None if name == '/b' and wall == 5 else now)
    assert watch.silences == [] and NOTICE > 1.0
    run(watch, 10, lambda name, wall, now: None if name == '/b' and wall in (5, 6) else now,
        t0=10.0)
    (b,) = watch.silences
    assert (b.node, b.wall_s, b.ended, b.dropped) == ('/b', 3.0, True, False)


def test_real_time_lag_and_a_node_that_leaves():
    """Without lockstep a node that answers late is named by how far sim time left it behind.

    A node that leaves the lockstep (the end of time) ends its silence.
    """
    watch = LockstepWatch(['/slow', '/late'], limit=10.0)
    lag = {'/slow': 2.0, '/late': 6.0}
    run(watch, 10, lambda name, wall, now: max(0.0, now - lag[name]), sim_rate=2.0)
    slow, late = sorted(watch.silences, key=lambda s: s.node)[::-1]
    assert (slow.node, slow.dropped) == ('/slow', False) and slow.lag_s == pytest.approx(2.0)
    assert (late.node, late.dropped) == ('/late', True) and late.lag_s == pytest.approx(6.0)
    assert slow.wall_s == 0.0, 'it answers: not silent on the wall clock'
    watch.answer('/late', END, 11.0)
    assert late.ended and '/late' not in watch.reached


def test_the_timeout_is_the_bridges(context):
    """The watch's timeout is the bridge's default ``lockstep_timeout``; the summary says both.

    With the watch off (every node in one process) there are no silences and no limits.
    """
    from scara_collab.nodes.pybullet_bridge import PARAMETERS
    from scara_collab.run.liveness import Liveness
    assert LOCKSTEP_TIMEOUT == PARAMETERS['lockstep_timeout']
    off = Liveness([], 10.0, context)
    assert off.summary() == {'silences': [], 'silence_limits': None}
    off.close()
    on = Liveness(['collision_monitor'], 10.0, context)
    try:
        on.expect(0.0)
        on.watch.look(5.0, 3.0)  # never answered since sim time started
        assert on.summary() == {
            'silences': [{'node': 'collision_monitor', 'sim_time': 0.0, 'wall_s': 3.0,
                          'lag_s': 5.0, 'ended': False, 'dropped': False}],
            'silence_limits': {'notice_s': NOTICE, 'lockstep_timeout_s': LOCKSTEP_TIMEOUT}}
    finally:
        on.close()
