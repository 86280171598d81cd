"""The job protocol's statuses alone (no node): typed fields <-> DiagnosticStatus key-values."""
from dataclasses import fields

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
import numpy as np
import pytest

from scara_collab.core.line import Handoff, OnBelt
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
    proto.LineHandoff(1, 12.34, 7, (Handoff(1_000_003, 'red', 0.1, 12.0),
                                    Handoff(1_000_004, 'blue', -0.2, 12.25)),
                      (OnBelt(1_000_009, 'green', 1.5, 0.05),)),
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


def test_every_status_says_how_each_of_its_fields_travels():
    """``FIELDS`` names exactly the dataclass's fields: none travels untold, none is extra."""
    for status in STATUSES:
        assert list(type(status).FIELDS) == [f.name for f in fields(status)], type(status)


def test_tables_and_records_travel_one_value_per_key_value():
    """A dict is one key-value per entry, a record one per value: no JSON in any value."""
    stats = STATUSES[5].to_msg()
    values = {kv.key: kv.value for kv in stats.values}
    assert values['counts.sorted'] == '3' and values['sorted_by.scara_right'] == '1'
    assert values['phases.scara_left'] == 'to_bin' and 'counts' not in values
    line = {kv.key: kv.value for kv in STATUSES[-1].to_msg().values}
    assert line['handoffs.1000004.cls'] == 'blue' and line['handoffs.1000004.time'] == '12.25'
    assert line['belt.1000009.x'] == '1.5' and 'handoffs' not in line
    for msg in (stats, STATUSES[-1].to_msg()):
        assert not any(kv.value[:1] in ('[', '{') for kv in msg.values)
    empty = proto.JobStats('single', False, 0.0, None)  # empty tables: no key-values at all
    assert proto.JobStats.from_msg(empty.to_msg()) == empty
    assert [kv.key for kv in empty.to_msg().values if '.' in kv.key] == []


def test_floats_come_back_exactly_and_nan_is_refused():
    """``repr`` both ways: every float, numpy's too, comes back to the bit; NaN does not."""
    for t in (0.1 + 0.2, 1e-300, 123456.78901234567, np.float64(2.0) / 3.0, float('inf')):
        event = proto.ItemEvent('sorted', 1, 'red', t)
        assert proto.ItemEvent.from_msg(event.to_msg()).time == t
    msg = STATUSES[5].to_msg()
    next(kv for kv in msg.values if kv.key == 'items_per_minute').value = 'nan'
    with pytest.raises(proto.ProtocolError, match='items_per_minute'):
        proto.JobStats.from_msg(msg)


def test_a_malformed_table_or_record_is_refused_with_the_reason():
    """A count that is no integer, a record short of a value or with a bad id: ProtocolError."""
    msg = STATUSES[5].to_msg()
    next(kv for kv in msg.values if kv.key == 'counts.sorted').value = '3.5'
    with pytest.raises(proto.ProtocolError, match='counts.sorted'):
        proto.JobStats.from_msg(msg)
    msg = STATUSES[-1].to_msg()
    msg.values = [kv for kv in msg.values if kv.key != 'handoffs.1000003.time']
    with pytest.raises(proto.ProtocolError, match=r"handoffs.1000003: no \['time'\]"):
        proto.LineHandoff.from_msg(msg)
    msg = STATUSES[-1].to_msg()
    msg.values.append(KeyValue(key='belt.x7.cls', value='red'))
    with pytest.raises(proto.ProtocolError, match='belt.x7.cls'):
        proto.LineHandoff.from_msg(msg)


def test_a_value_of_the_wrong_kind_is_refused_when_sent():
    """A float count or a text where a number goes fails at ``to_msg``, not at the receiver."""
    with pytest.raises(TypeError, match='not an integer'):
        proto.JobStats('single', True, 1.0, 0.0, counts={'sorted': 2.0}).to_msg()
    with pytest.raises(TypeError, match='not a number'):
        proto.ItemEvent('sorted', 1, 'red', '1.0').to_msg()
