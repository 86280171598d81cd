"""The launcher's exit status tells the truth: a foreign /clock mid-run fails a finished run.

A real launch (separate processes, the session's ROS_DOMAIN_ID: conftest.py), as in
``test_launcher.py``; the verdict itself is tested on summaries in ``test_verdict.py``.
"""
import json
import time

from test_launcher import launch  # noqa: F401 (the fixture: start(*args) launches)


def test_a_second_clock_publisher_mid_run_fails_the_run(launch, tmp_path):  # noqa: F811
    """A /clock publisher that appears mid-run is named; the run ends at its duration, exit 6.

    The reason is the report's first line and ``exit_reason`` in ``summary.json``.
    """
    import rclpy
    from rosgraph_msgs.msg import Clock
    out = tmp_path / 'foreign'
    la = launch('--mode', 'idle', '--duration', '6', '--rtf', '1', '--output', str(out),
                '--no-plots', '--one-process')  # every node at once: the quickest start
    la.wait_for_line(r'\[launch\] graph idle at sim t=')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('rogue_clock', context=ctx)
    try:
        node.create_publisher(Clock, '/clock', 10)  # there, publishing nothing yet
        time.sleep(4.0)  # a few of the recorder's looks (one a wall second)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert la.wait() == 6, la.output
    assert 'scara_collab run: mode idle, FAILED, exit 6: a second /clock publisher at sim t=' \
        in la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_code'] == 6 and summary['end_reason'] == 'duration reached'
    assert summary['exit_reason'].startswith('a second /clock publisher at sim t=')
    assert summary['interrupted'] is False
    assert len(summary['foreign_clocks']) == 1, summary['foreign_clocks']
    (seen,) = summary['foreign_clocks']
    assert seen['publishers'] == 2 and seen['nodes'] == ['/pybullet_bridge', '/rogue_clock']
    assert 0.0 < seen['time'] < 6.0
    assert summary['problems'] == [{'code': 6, 'text': summary['exit_reason']}]
    report = (out / 'report.txt').read_text().splitlines()
    assert report[0].startswith('scara_collab run: mode idle, FAILED, exit 6: ')


def test_two_launchers_at_once_on_one_domain_do_not_both_pass(launch, tmp_path):  # noqa: F811
    """Two launchers started at the same moment on one domain both pass the start-up check.

    Their graphs merge; each names the other's graph (and clock) while it runs, so they do not
    both exit 0, and a failing one says why in its summary.
    """
    runs = [launch('--mode', 'idle', '--duration', '6', '--rtf', '1', '--output',
                   str(tmp_path / f'twin_{k}'), '--no-plots', '--one-process')
            for k in range(2)]
    codes = [la.wait() for la in runs]
    assert codes != [0, 0], '\n'.join(la.output for la in runs)
    for k, code in enumerate(codes):
        summary_file = tmp_path / f'twin_{k}' / 'summary.json'
        if code != 0 and summary_file.is_file():
            summary = json.loads(summary_file.read_text())
            named = ' '.join(p['text'] for p in summary.get('problems', []))
            assert summary.get('second_graphs') or summary.get('foreign_clocks') \
                or 'second' in named or 'graph' in named, summary.get('exit_reason')
