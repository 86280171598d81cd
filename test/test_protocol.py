"""The job protocol's statuses alone (no node): typed fields <-> DiagnosticStatus key-values."""
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
import pytest

from scara_collab.nodes import protocol as proto

STATUSES = [
    proto.PlannerStatus('scara_left', 'planned', 'scara_left/1500000000', request=1500000000,
                        start=1.5, end=2.75, delay=0.25, kind='line'),
    proto.PlannerStatus('scara_right', 'refused', 'scara_right/7', request=7,
                        reason='unreachable: beyond the outer reach'),
    proto.ExecutionStatus('scara_left', 'accepted', 'scara_left/15', time=1.0, start=1.2,
                          end=3.0, stamp=1.0),
    proto.ExecutionStatus('scara_right', 'preempted', 'scara_right/9', time=4.0,
                          by='scara_right/hold'),
    proto.ItemEvent('missed', 12, 'red', 30.5, cause='rode off the belt'),
    proto.JobStats('collaborative', True, 12.0, 0.5, counts={'sorted': 3}, sorted_by={
        'scara_left': 2, 'scara_right': 1}, items_per_minute=15.6, give_ups=1, retries=2,
        phases={'scara_left': 'to_bin'}, last_give_up='t=3.00 s scara_left to_item: why'),
    proto.MirrorStatus(True, 3.0, error=1e-4, error_max=2e-4, error_max_time=2.5,
                       in_step_moves=4),
    proto.MonitorStatus(5.0, 0.4, 0.2, 4.0, 0.1, True, reason='margin broken',
                        kind='emergency', emergency=1),
    proto.StopEvent('protective', 'end', 7.0, 'predicted conflict', since=6.5),
    proto.SimStatus(8.0, False, False, 1, 3),
]


@pytest.mark.parametrize('status', STATUSES, ids=lambda s: type(s).__name__)
def test_every_status_comes_back_from_its_message_unchanged(status):
    """``from_msg(to_msg(s)) == s``, exactly (floats included), for every kind of status."""
    msg = status.to_msg()
    assert isinstance(msg, DiagnosticStatus) and msg.name == status.name()
    assert msg.level == proto.LEVELS[status.level()] and msg.message == status.text()
    assert type(status).from_msg(msg) == status


def test_levels_and_texts_say_what_went_wrong():
    """A refusal is an error, a wait or a delay a warning; the text names the move and why."""
    refused, planned = STATUSES[1], STATUSES[0]
    assert refused.level() == 'ERROR' and 'unreachable' in refused.text()
    assert planned.level() == 'WARN' and 'delayed by 0.25 s' in planned.text()
    assert proto.ItemEvent('sorted', 1, 'red', 1.0, robot='scara_left').level() == 'OK'
    assert STATUSES[7].level() == 'ERROR' and STATUSES[7].text().startswith('emergency stop')
    assert STATUSES[2].late == pytest.approx(0.2) and STATUSES[3].late == 0.0


def test_a_malformed_message_is_refused_with_the_reason():
    """A missing field, a bad number, an unknown state: ProtocolError naming it."""
    msg = STATUSES[0].to_msg()
    msg.values = [kv for kv in msg.values if kv.key != 'request']
    with pytest.raises(proto.ProtocolError, match="no 'request'"):
        proto.PlannerStatus.from_msg(msg)
    msg = STATUSES[0].to_msg()
    for kv in msg.values:
        if kv.key == 'start':
            kv.value = 'nan'
    with pytest.raises(proto.ProtocolError, match='start'):
        proto.PlannerStatus.from_msg(msg)
    msg = STATUSES[0].to_msg()
    next(kv for kv in msg.values if kv.key == 'state').value = 'lost'
    with pytest.raises(proto.ProtocolError, match='state'):
        proto.PlannerStatus.from_msg(msg)
    with pytest.raises(ValueError):
        proto.ItemEvent('vanished', 1, 'red', 0.0)
    optional = DiagnosticStatus(values=[KeyValue(key=k, value=v) for k, v in (
        ('kind', 'spawned'), ('item', '4'), ('cls', 'blue'), ('time', '2.0'))])
    assert proto.ItemEvent.from_msg(optional) == proto.ItemEvent('spawned', 4, 'blue', 2.0)
