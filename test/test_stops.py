"""The run's stops (records.stops): stop events, the monitor's status, /emergency_stop holds."""
import pytest

from scara_collab.records.stops import StopLog


def kinds(log, t_end):
    """Return ``(protective, emergency)`` lists of ``(time, lost, standing, cause)``."""
    out = log.summary(t_end)
    return tuple([(s['time'], s['lost'], s['standing'], s['cause']) for s in out[k]]
                 for k in ('protective_stops', 'emergency_stops'))


def test_begins_and_ends_give_each_stop_its_cost():
    """Each begin and end pair is one stop; a begin without its end stands to the run's end."""
    log = StopLog()
    log.event('protective', 'begin', 10.0, 'predicted breach')
    log.event('protective', 'begin', 10.0, 'predicted breach')  # delivered twice
    log.event('protective', 'end', 10.5, 'arms at rest', since=10.0)
    log.event('protective', 'end', 10.5, 'arms at rest', since=10.0)
    log.event('protective', 'begin', 20.0, 'no valid joint state for 0.200 s')
    log.event('protective', 'end', 20.25, 'overridden by an emergency stop', since=20.0)
    log.event('emergency', 'begin', 20.25, 'margin broken')
    protective, emergency = kinds(log, 60.0)
    assert protective == [(10.0, 0.5, False, 'predicted breach'),
                          (20.0, 0.25, False, 'no valid joint state for 0.200 s')]
    assert emergency == [(20.25, pytest.approx(39.75), True, 'margin broken')]
    log.event('emergency', 'end', 61.0, 'cleared', since=20.25)  # during the shutdown
    assert kinds(log, 60.0)[1] == [(20.25, pytest.approx(40.75), False, 'margin broken')]


def test_lost_messages_and_late_stops():
    """An end without its begin is still a stop; one that begins after the run is not its."""
    log = StopLog()
    log.event('protective', 'end', 5.0, 'arms at rest', since=4.2)
    log.event('emergency', 'begin', 80.0, 'margin broken')  # after the run's end (60)
    protective, emergency = kinds(log, 60.0)
    assert protective == [(4.2, pytest.approx(0.8), False,
                           '(begin not heard; released: arms at rest)')]
    assert emergency == []
    with pytest.raises(ValueError):
        log.event('protective', 'paused', 1.0, '')
    with pytest.raises(ValueError):
        log.event('safety', 'begin', 1.0, '')


def test_the_monitors_newest_status_has_the_last_word():
    """A stop the monitor still reports stands; a newer status without it ends a lost end."""
    log = StopLog()
    log.monitor(30.0, True, 'emergency', 'margin broken')  # its begin event was lost
    log.monitor(31.0, True, 'emergency', 'margin broken')
    assert kinds(log, 40.0)[1] == [(30.0, 10.0, True, 'margin broken')]
    log = StopLog()
    log.event('protective', 'begin', 12.0, 'predicted breach')
    log.monitor(11.0, False, '', '')  # older than the begin: says nothing about it
    assert kinds(log, 40.0)[0][0][2] is True
    log.monitor(13.0, False, '', '')  # newer: the end event was lost
    assert kinds(log, 40.0)[0] == [(12.0, 1.0, False, 'predicted breach')]
    log = StopLog()  # a status older than the end heard: not a new stop
    log.event('protective', 'begin', 12.0, 'predicted breach')
    log.monitor(12.0, True, 'protective', 'predicted breach')
    log.event('protective', 'end', 12.4, 'arms at rest', since=12.0)
    assert kinds(log, 40.0)[0] == [(12.0, pytest.approx(0.4), False, 'predicted breach')]
    old = StopLog()  # a monitor that says no kind: an emergency stop
    old.monitor(7.0, True, '', 'unusable joint state')
    assert kinds(old, 9.0)[1] == [(7.0, 2.0, True, 'unusable joint state')]


def test_emergency_stop_holds_without_an_event_are_listed_once():
    """A hold on /emergency_stop no stop event covers is an emergency stop; one covered is not."""
    log = StopLog()
    log.request(False, 0.0)  # the latched initial false
    log.request(True, 15.0)
    log.request(True, 15.5)  # still held
    log.request(False, 18.0)
    log.request(True, 40.2)  # the monitor's own stop, its event stamped a little earlier
    log.event('emergency', 'begin', 40.0, 'margin broken')
    _, emergency = kinds(log, 50.0)
    assert emergency == [(15.0, 3.0, False, 'held on /emergency_stop (no stop event heard)'),
                         (40.0, 10.0, True, 'margin broken')]
