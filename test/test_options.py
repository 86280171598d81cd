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
])
def test_a_bad_argument_is_a_usage_error(argv, message, capsys):
    """Each bad value or combination exits 2 with a message naming the option."""
    with pytest.raises(SystemExit) as exc:
        parse_options(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
