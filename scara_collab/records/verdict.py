"""The run's verdict: its exit code and the reason, from its summary alone (no rclpy).

A run exits 0 only if it tells a clean story: the margin held, no node died or went silent
beyond the bridge's patience, no stop was left standing, nobody else's clock or graph was on
the domain, and a person in the cell (the summary's ``person`` block) never touched a moving
arm nor came within its protective separation. :func:`verdict` reads that from the summary
(``summary.json``'s fields), in one place; :meth:`scara_collab.records.record.RunRecord.finish`
writes its ``exit_code``, ``exit_reason`` and ``problems`` into the summary, the report prints
the reason first, and the launcher exits with the code.

====  =======================================================================================
code  meaning (:data:`EXIT_CODES`)
====  =======================================================================================
0     a clean run
1     a node died, stopped answering (``--silent-timeout``), was not ready or refused to start
2     bad arguments
3     the margin was broken: the minimum separation fell below the safety margin
4     a stop (protective or emergency) was still standing at the end of the run, or the
      separation monitor's fault (a silent or broken scanner: every arm stopped)
5     a node was silent longer than the bridge's ``lockstep_timeout``: sim time went on
      without it (every silence is named, whatever its length; only these fail)
6     a foreign clock (a second ``/clock`` publisher, sim time going backwards) or a second
      graph (a second bridge, automation manager, ... on the domain)
8     a person unguarded: the person touched a moving arm (``contacts_while_moving``), or came
      within a moving arm's protective separation (``min_ssm_margin_m`` below 0), from the
      ground truth
130   SIGINT, 143 SIGTERM
====  =======================================================================================

The launcher's own code (1, 2, 130, 143: the run ended early) comes first; otherwise the first
problem in the order 6, 3, 8, 5, 4 (a foreign graph first, whose commands can break anything;
the broken safety figures next, arms then person; then the causes before their consequences:
a silent guard leaves a stop standing) gives the code and the reason. (7 is a line's: a lost
handoff, :mod:`scara_collab.records.line_report`.)
``problems`` lists every one, the launcher's first.

>>> clean = {'exit_code': 0, 'exit_reason': 'duration reached', 'min_separation_m': 0.13,
...          'safety_margin_m': 0.1}
>>> verdict(clean).code, verdict(clean).reason
(0, 'duration reached')
>>> broken = dict(clean, min_separation_m=0.08, min_separation_time=12.5)
>>> verdict(broken).code, verdict(broken).reason
(3, 'margin broken: minimum separation 0.080 m < 0.1 m at sim t=12.50 s')
"""
from dataclasses import dataclass, field
from typing import Dict, List

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_MARGIN = 3
EXIT_STOP_STANDING = 4
EXIT_SILENT = 5
EXIT_FOREIGN = 6
EXIT_PERSON = 8
EXIT_SIGINT = 130
EXIT_SIGTERM = 143

#: every exit status of a run and what it means
EXIT_CODES: Dict[int, str] = {
    EXIT_OK: 'clean run',
    EXIT_FAILED: 'a node died / stopped answering / was not ready / refused to start',
    EXIT_USAGE: 'bad arguments',
    EXIT_MARGIN: 'margin broken',
    EXIT_STOP_STANDING: 'a stop left standing at the end',
    EXIT_SILENT: "a node silent longer than the bridge's lockstep_timeout",
    EXIT_FOREIGN: 'a foreign clock or a second graph on the domain',
    EXIT_PERSON: 'a person touched a moving arm or came within its protective separation',
    EXIT_SIGINT: 'SIGINT',
    EXIT_SIGTERM: 'SIGTERM',
}
#: the order in which the summary's problems decide the code (a cause before its consequences)
PRIORITY = (EXIT_FOREIGN, EXIT_MARGIN, EXIT_PERSON, EXIT_SILENT, EXIT_STOP_STANDING)


@dataclass(frozen=True)
class Verdict:
    """The exit ``code``, its ``reason`` (one line) and every problem (``code``, ``text``)."""

    code: int
    reason: str
    problems: List[Dict[str, object]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Return True for a clean run (exit 0)."""
        return self.code == EXIT_OK


def _t(value) -> str:
    return 'n/a' if value is None else f'{value:.2f}'


def _foreign(s: Dict) -> List[str]:
    out = [f'a second /clock publisher at sim t={_t(c.get("time"))} s: {c.get("publishers")} '
           f'publishers ({", ".join(c.get("nodes") or [])})'
           for c in s.get('foreign_clocks') or []]
    jumps = s.get('clock_jumps_back') or []
    if jumps:
        count = s.get('clock_jumps_back_count') or len(jumps)
        out.append(f'/clock went backwards {count} time(s), first at sim t='
                   f'{jumps[0].get("time"):.3f} s (to {jumps[0].get("to"):.3f} s): a foreign '
                   'clock')
    out += [f'a second graph on the domain at sim t={_t(g.get("time"))} s: '
            + ', '.join(f'{n} nodes named {name}' for name, n in (g.get('nodes') or {}).items())
            for g in s.get('second_graphs') or []]
    return out


def _margin(s: Dict) -> List[str]:
    sep, margin = s.get('min_separation_m'), s.get('safety_margin_m')
    if sep is None or margin is None or sep >= margin:
        return []
    return [f'margin broken: minimum separation {sep:.3f} m < {margin:g} m at sim '
            f't={_t(s.get("min_separation_time"))} s']


def _silent(s: Dict) -> List[str]:
    limit = (s.get('silence_limits') or {}).get('lockstep_timeout_s')
    over = f" (the bridge's lockstep_timeout {limit:g} s)" if limit else ''
    return [f'node {x.get("node")} silent {x.get("wall_s", 0.0):.1f} s wall, '
            f'{x.get("lag_s", 0.0):.1f} s sim behind, from sim t={_t(x.get("sim_time"))} s: '
            f'longer than the lockstep waits{over}; sim time went on without it'
            for x in s.get('silences') or [] if x.get('dropped')]


def _standing(s: Dict) -> List[str]:
    out = [f'{kind} stop standing at the end of the run, since sim t={_t(x.get("time"))} s: '
           f'{x.get("cause")}'
           for kind in ('emergency', 'protective')
           for x in s.get(f'{kind}_stops') or [] if isinstance(x, dict) and x.get('standing')]
    person = s.get('person')
    if isinstance(person, dict) and person.get('fault_at_end'):
        out.append('protective stop standing at the end of the run, since sim t='
                   f'{_t(person.get("fault_since"))} s: separation monitor: '
                   f'{person["fault_at_end"]}')
    return out


def _person(s: Dict) -> List[str]:
    p = s.get('person')
    if not isinstance(p, dict):
        return []
    out = []
    contacts = p.get('contacts_while_moving') or 0
    if contacts > 0:
        first = p.get('first_contact_while_moving') or {}
        out.append(f'a person touched a moving arm: {contacts} contact(s), the first with '
                   f'{first.get("robot")} at sim t={_t(first.get("time"))} s')
    least = p.get('min_ssm_margin_m')
    if least is not None and least < 0.0:
        out.append(f'protective separation broken: S - S_p {least:.3f} m < 0 for '
                   f'{p.get("min_ssm_margin_robot")} while it moved, at sim '
                   f't={_t(p.get("min_ssm_margin_time"))} s (ground truth)')
    return out


CHECKS = {EXIT_FOREIGN: _foreign, EXIT_MARGIN: _margin, EXIT_PERSON: _person,
          EXIT_SILENT: _silent, EXIT_STOP_STANDING: _standing}


def verdict(summary: Dict) -> Verdict:
    """Return the run's exit code, reason and problems from its summary.

    :param summary: the run's summary (``summary.json``): the launcher's ``exit_code`` and
        ``exit_reason`` (how the run ended; no code counts as 0), ``min_separation_m``,
        ``safety_margin_m``, ``protective_stops``, ``emergency_stops``, ``silences``,
        ``foreign_clocks``, ``clock_jumps_back``, ``second_graphs``, ``person``
        (``contacts_while_moving``, ``min_ssm_margin_m``, ``fault_at_end``); missing ones
        are not checked.
    :return: the launcher's code and reason if it is not 0 (1 for a run ``interrupted``
        without one), else those of the first problem in :data:`PRIORITY` order, else 0 and
        the launcher's reason.
    """
    code = int(summary.get('exit_code') or EXIT_OK)
    reason = str(summary.get('end_reason') or summary.get('exit_reason') or '')
    if code == EXIT_OK and summary.get('interrupted'):  # ended early, no launcher to say how
        code = EXIT_FAILED
    problems = [{'code': code, 'text': reason}] if code != EXIT_OK else []
    problems += [{'code': c, 'text': text} for c in PRIORITY for text in CHECKS[c](summary)]
    if code == EXIT_OK and problems:
        code, reason = problems[0]['code'], str(problems[0]['text'])
    return Verdict(code, reason, problems)


def apply(summary: Dict) -> Verdict:
    """Write the verdict into ``summary``: ``exit_code``, ``exit_reason``, ``problems``.

    ``end_reason`` keeps how the run ended (``'duration reached'``, ``'SIGINT'``, ...). Once
    per summary: its ``exit_code`` is the launcher's until then, the verdict's after.
    """
    if 'end_reason' not in summary:
        summary['end_reason'] = summary.get('exit_reason')
    result = verdict(summary)
    summary.update(exit_code=result.code, exit_reason=result.reason, problems=result.problems)
    return result
