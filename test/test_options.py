"""The launcher's options: one frozen value, resolved from the command line, bad ones refused."""
import dataclasses
from pathlib import Path

import pytest

from scara_collab.core.config import load_config
from scara_collab.run.options import FAST_CHUNK, parse_options


def test_the_defaults_are_resolved_from_the_configuration():
    """What the command line leaves open is filled in once: factors, chunk, namespace, flags."""
    opts = parse_options([])
    assert opts.rtf == float(load_config('simulation')['real_time_factor'])
    assert opts.launch_rtf == opts.rtf and opts.step_chunk is None  # 1x: no hold, no chunk
    assert opts.mode == 'collaborative' and opts.lockstep is True and opts.lockstep_name == 'on'
    assert opts.namespace == '' and opts.cells == 1 and opts.cell == 0
    assert opts.faults == () and opts.plots is True and opts.output is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.duration = 1.0  # one value for the whole run


def test_the_launch_pace_and_the_bridge_chunk_follow_the_release():
    """Held at --launch-rtf below --rtf; a fast chunk only for a release beyond 4x."""
    fast = parse_options(['--rtf', '0'])
    assert (fast.rtf, fast.launch_rtf, fast.step_chunk) == (0.0, 1.0, FAST_CHUNK)
    two = parse_options(['--rtf', '2'])
    assert (two.launch_rtf, two.step_chunk) == (1.0, None)
    assert parse_options(['--rtf', '8']).step_chunk == FAST_CHUNK
    assert parse_options(['--rtf', '8', '--step-chunk', '0.01']).step_chunk == 0.01
    direct = parse_options(['--rtf', '0', '--launch-rtf', '0'])
    assert (direct.launch_rtf, direct.step_chunk) == (0.0, None)  # no hold
    slow = parse_options(['--rtf', '0.5', '--launch-rtf', '3'])
    assert slow.launch_rtf == 0.5  # never faster than the run


def test_the_fields_are_typed_values():
    """Flags become booleans, repeated faults a tuple, a line cell its namespace."""
    opts = parse_options(['--lockstep', 'off', '--no-plots', '--one-process', '--fault',
                          'drop:/a/gripper:1', '--fault', 'latency:/joint_states:0.02:0.01',
                          '--output', 'x', '--cells', '3', '--line-cell', '2'])
    assert opts.lockstep is False and opts.lockstep_name == 'off'
    assert opts.plots is False and opts.one_process is True and opts.output == Path('x')
    assert opts.faults == ('drop:/a/gripper:1', 'latency:/joint_states:0.02:0.01')
    assert (opts.namespace, opts.cell, opts.cells) == ('/cell_2', 2, 3)
    assert parse_options(['--namespace', 'cell_1/']).namespace == '/cell_1'


@pytest.mark.parametrize('argv, message', [
    (['--duration', '0'], '--duration must be > 0'),
    (['--rtf', '-1'], '--rtf must be >= 0'),
    (['--launch-rtf', '-1'], '--launch-rtf must be >= 0'),
    (['--feed-interval', '0'], '--feed-interval must be > 0'),
    (['--fault', 'drop:nothing'], '--fault: '),
    (['--cells', '0'], '--cells must be >= 1'),
    (['--cells', '2', '--line-cell', '2'], '--line-cell 2 is not a cell of a line of 2'),
    (['--discovery-server', '70000'], '--discovery-server: a UDP port'),
    (['--cells', '2', '--line-cell', '0', '--discovery-server'],
     '--discovery-server starts a server for a whole line'),
    (['--cells', '2', '--namespace', 'x'], '--namespace and --cells'),
    (['--cells', '2', '--gui'], '--viewer and --gui show one cell'),
    (['--namespace', 'cell 1'], '--namespace: '),
    (['--step-chunk', '0'], '--step-chunk must be > 0'),
    (['--silent-timeout', '0'], '--silent-timeout must be > 0'),
    (['--viewer', '0'], '--viewer PORT must be in 1..65535'),
    (['--mode', 'dancing'], "invalid choice: 'dancing'"),
    (['--person', 'nowhere'], "--person: 'nowhere' is neither a built-in scenario (pass-by, "),
    (['--person-cell', '0'], '--person-cell needs --person'),
    (['--person', 'inlet', '--cells', '2', '--person-cell', '2'],
     '--person-cell 2 is not a cell of a line of 2'),
])
def test_a_bad_argument_is_a_usage_error(argv, message, capsys):
    """Each bad value or combination exits 2 with a message naming the option."""
    with pytest.raises(SystemExit) as exc:
        parse_options(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_person_is_a_built_in_scenario_or_a_yaml_file_seeded_like_the_feed(tmp_path):
    """``--person``: a built-in name or a file's absolute path, the feed's seed; none by default.

    In a line, every cell has the person, or only ``--person-cell K``.
    """
    none = parse_options([])
    assert (none.person, none.cell_person, none.person_seed) == (None, None, None)
    assert parse_options(['--person', 'none']).person is None
    inlet = parse_options(['--person', 'inlet'])
    assert (inlet.cell_person, inlet.person_seed) == (
        'inlet', load_config('simulation')['item_seed'])
    assert parse_options(['--person', 'random', '--seed', '3']).person_seed == 3
    walk = tmp_path / 'walk.yaml'
    walk.write_text('visits:\n  - start: 2.0\n    speed: 1.2\n    waypoints: [[-6.0, -3.0], '
                    '[-6.0, 3.0]]\n')
    assert parse_options(['--person', str(walk)]).person == str(walk.resolve())
    line = ['--person', 'middle', '--cells', '2', '--line-cell']
    assert parse_options(line + ['1']).cell_person == 'middle'
    assert parse_options(line + ['1', '--person-cell', '0']).cell_person is None
    assert parse_options(line + ['0', '--person-cell', '0']).cell_person == 'middle'


@pytest.mark.parametrize('text, message', [
    ('visits: [', 'not valid YAML'),
    ('visits: []\n', 'a scenario is {visits: [...]}'),
    ('visits:\n  - start: 0.0\n    waypoints: [[0, 0]]\n', 'start must be >= 1.0 s'),
])
def test_a_person_file_that_is_not_a_scenario_is_a_usage_error(tmp_path, capsys, text, message):
    """A file that does not parse as a scenario exits 2, saying what is wrong with it."""
    bad = tmp_path / 'bad.yaml'
    bad.write_text(text)
    with pytest.raises(SystemExit) as exc:
        parse_options(['--person', str(bad)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert '--person: ' in err and message in err
