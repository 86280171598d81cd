"""The start rule: every hop's formula, the lateness it measures, and that it is the only one."""
import ast
from pathlib import Path

import pytest

from scara_collab.core.move_time import (Lateness, lateness, Leads, MoveTime, Refused,
                                         stamp_time, start_time)

PACKAGE = Path(__file__).resolve().parents[1] / 'scara_collab'
LEAD_FIELDS = {'decision', 'move', 'pair', 'planning', 'send'}
#: the names the leads had as settings of their own, before they were one value
OLD_NAMES = {'decision_lead', 'move_lead', 'pair_lead', 'planning_lead', 'send_margin'}


def test_each_hop_adds_its_lead_to_the_time_it_is_given():
    """Job, planner: the start is ``now`` plus the hop's lead plus the measured lateness."""
    clock = MoveTime(Leads(decision=0.1, move=0.05, pair=0.2, planning=0.07, send=0.03))
    assert clock.decided(1.0) == 1.0 + 0.1
    assert clock.decided(1.0, mirrored=True) == 1.0 + 0.1 + 0.2
    assert clock.asap(1.0) == 1.0 + 0.05 and clock.asap(1.0, mirrored=True) == 1.0 + 0.2
    assert clock.wanted(0.0, 1.0) == 1.0 + 0.07 and clock.wanted(3.0, 1.0) == 3.0
    assert clock.sendable(1.01, 1.0) == 1.0 + 0.03 and clock.sendable(2.0, 1.0) == 2.0
    assert clock.requested(1.0, 1.0) == pytest.approx(1.001) and clock.requested(2.0, 1.0) == 2.0


def test_lateness_is_measured_once_and_added_where_the_rule_says():
    """The job aims with the typical lateness, the planner waits with the worst."""
    clock = MoveTime(Leads())
    for start in (10.0, 10.04, 10.0):       # one move 40 ms late among three
        clock.started(stamp=10.0, start=start)
    clock.started(stamp=0.0, start=12.0)    # unstamped: on time by definition
    assert clock.late.worst == pytest.approx(0.04) and clock.late.typical == 0.0
    assert clock.asap(20.0) == 20.0 + clock.leads.move
    assert clock.wanted(0.0, 20.0) == pytest.approx(20.0 + clock.leads.planning + 0.04)
    assert clock.sendable(0.0, 20.0) == pytest.approx(20.0 + clock.leads.send + 0.04)
    assert clock.ahead(20.05, 20.0) and not clock.ahead(20.03, 20.0)
    assert lateness(10.0, 9.0) == 0.0 and lateness(None, 9.0) == 0.0


def test_the_bridges_start_and_the_stamp_grid():
    """Stamp 0 or past: now (late); future: the stamp; ended: refused; stamps in whole ns."""
    assert start_time(0.0, 1.0, 5.0, 0.001) == 5.0 and start_time(5.5, 1.0, 5.0, 0.001) == 5.5
    assert start_time(4.2, 1.0, 5.0, 0.001) == 5.0
    with pytest.raises(Refused, match='ended 0.500 s ago'):
        start_time(3.5, 1.0, 5.0, 0.001)
    assert stamp_time(190.70000000000002 + 0.05) == 190.75


def test_the_leads_are_checked_and_read_from_the_config_files():
    """A lead that is not > 0 is refused, named as in the config files."""
    with pytest.raises(ValueError, match='send_margin must be > 0'):
        Leads(send=0.0)
    leads = Leads.of({'decision_lead': 0.2, 'mirror_start_lead': 0.3}, {'planning_lead': 0.04},
                     send_margin=0.06)
    assert leads == Leads(decision=0.2, move=0.04, pair=0.3, planning=0.04, send=0.06)
    window = Lateness(window=2)
    for s in (0.3, 0.0, 0.0):
        window.add(s)
    assert window.worst == 0.0


def _lead_reads(path: Path) -> list:
    """Return where a module reads a lead: ``x.leads.<field>`` or a lead's old setting name."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Attribute):
            continue
        through_leads = (node.attr in LEAD_FIELDS and isinstance(node.value, ast.Attribute)
                         and node.value.attr == 'leads')
        if through_leads or node.attr in OLD_NAMES:
            out.append(f'{path.relative_to(PACKAGE)}:{node.lineno} .{node.attr}')
    return out


def test_only_the_start_rule_reads_the_leads():
    """A second start formula would read a lead: only ``core/move_time.py`` does."""
    rule = PACKAGE / 'core' / 'move_time.py'
    assert _lead_reads(rule)  # the check sees the reads where they are
    others = [hit for path in sorted(PACKAGE.rglob('*.py')) if path != rule
              for hit in _lead_reads(path)]
    assert others == []
