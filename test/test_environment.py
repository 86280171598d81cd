"""The node processes get the launcher's own Python environment's ROS, whatever started it.

A launcher started from a process that another venv's ROS wheels had set up (its library
path, their start-up marker) runs its nodes on its own venv's libraries: the bridge loads
``control_msgs`` and the run reaches sim time. Where a package's type support does not load,
it counts as absent (:mod:`scara_collab.nodes.optional_interfaces`).
"""
import json
import os
from pathlib import Path
import subprocess
import sys

import pytest

from scara_collab.run import environment as ev

ROOT = Path(__file__).resolve().parents[1]
LAUNCHER = ROOT / 'scripts' / 'launch_cell.py'
PREFIX = Path(sys.prefix)
WHEELS = (ev.site_packages(PREFIX) / ev.BOOTSTRAPPER).is_file()
BUILT = any((PREFIX / 'lib').glob('libcontrol_msgs__rosidl_generator_py.so'))


def make_venv(root: Path, libs=('ros_a.libs',), wheels: bool = True) -> Path:
    """Make the folders of a venv at ``root`` with the ROS wheels' start-up and ``libs``."""
    site = ev.site_packages(root)
    site.mkdir(parents=True)
    (root / 'pyvenv.cfg').write_text('home = /usr/bin\n')
    if wheels:
        (site / ev.BOOTSTRAPPER).write_text('import ros_wheels_bootstrapper\n')
    for name in libs:
        (site / name).mkdir()
    return root


def test_a_child_gets_its_own_venvs_libraries_and_none_of_another(tmp_path):
    """The own venv's lib/ and ros_*.libs first, the user's folders kept, the other venv's not."""
    tmp = tmp_path.resolve()
    ours = make_venv(tmp / 'ours', ('ros_rcl.libs', 'ros_rclpy.libs'))
    theirs = make_venv(tmp / 'theirs', ('ros_rclpy.libs',))
    user = tmp / 'cuda' / 'lib64'
    loose = tmp / 'home' / '.local' / 'site-packages' / 'ros_rcl.libs'  # a wheel, no venv
    for folder in (user, loose):
        folder.mkdir(parents=True)
    site = ev.site_packages(ours)
    own = [str(ours / 'lib'), str(site / 'ros_rcl.libs'), str(site / 'ros_rclpy.libs')]
    assert ev.wheel_libraries(ours) == own
    inherited = os.pathsep.join([
        str(theirs / 'lib'), str(user), str(ev.site_packages(theirs) / 'ros_rclpy.libs'),
        str(loose), own[0], '', str(user)])
    env = ev.node_environment({ev.LIBRARY_PATH: inherited, ev.MARKER: '1', 'HOME': '/h'},
                              ours)
    assert env[ev.LIBRARY_PATH].split(os.pathsep) == own + [str(user)]
    assert env[ev.MARKER] == '1' and env['HOME'] == '/h'  # set up: no second start
    # the launcher not started from anything: the same libraries, the same order
    assert ev.node_environment({'HOME': '/h'}, ours) == env | {
        ev.LIBRARY_PATH: os.pathsep.join(own)}
    # a Python without the ROS wheels (a sourced ROS install): only the other venv goes
    plain = make_venv(tmp / 'plain', (), wheels=False)
    env = ev.node_environment({ev.LIBRARY_PATH: inherited, ev.MARKER: '1'}, plain)
    assert env[ev.LIBRARY_PATH] == str(user) and ev.MARKER not in env
    assert ev.LIBRARY_PATH not in ev.node_environment({ev.MARKER: '1'}, plain)


def test_the_launchers_children_get_this_pythons_environment():
    """The supervisor's environment is :func:`node_environment` of this process's own."""
    from scara_collab.run.supervisor import Supervisor
    env = Supervisor(Path('/nowhere'), Path('/cfg'), None).env()
    assert env == ev.node_environment(os.environ) | {
        'PYTHONUNBUFFERED': '1', 'RCUTILS_COLORIZED_OUTPUT': '0',
        'SCARA_LAUNCHER_PID': str(os.getpid())}
    if WHEELS:
        assert env[ev.LIBRARY_PATH].startswith(str(PREFIX.resolve() / 'lib'))


def foreign_environment(tmp_path: Path) -> dict:
    """Return this process's environment as another venv's ROS wheels would have set it up.

    The other venv has the same ROS wheels but not ``scripts/build_interfaces``' packages: its
    ``lib/`` holds this venv's libraries but those of ``control_msgs`` and ``tf2_msgs``.
    """
    other = make_venv(tmp_path / 'other', ())
    lib = other / 'lib'
    site = ev.site_packages(PREFIX)
    for path in [*(PREFIX / 'lib').glob('*.so*'), *site.glob('ros_*.libs/*')]:
        link = lib / path.name  # the same library in two wheels: once
        if not ('control_msgs' in path.name or 'tf2_msgs' in path.name or link.is_symlink()):
            link.symlink_to(path.resolve())
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    env[ev.LIBRARY_PATH] = os.pathsep.join([str(lib), str(tmp_path / 'nothing_here')])
    env[ev.MARKER] = '1'
    return env


needs_built = pytest.mark.skipif(not (WHEELS and BUILT), reason='needs the ROS wheels and '
                                 'control_msgs, tf2_msgs built (./scripts/build_interfaces)')


@needs_built
def test_a_type_support_that_does_not_load_is_absent_with_its_reason(tmp_path):
    """With another venv's libraries, control_msgs imports but does not load: absent, said why."""
    code = ('import json\n'
            'from scara_collab.nodes.optional_interfaces import optional_interface\n'
            'out = [optional_interface(m, n) for m, n in (("control_msgs.action", '
            '"FollowJointTrajectory"), ("tf2_msgs.msg", "TFMessage"), ("std_msgs.msg", '
            '"String"))]\n'
            'print(json.dumps([[i.name, i.type is None, i.installed, i.reason] for i in out]))\n')
    proc = subprocess.run([sys.executable, '-c', code], env=foreign_environment(tmp_path),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    (control, tf, string) = json.loads(proc.stdout.splitlines()[-1])
    for name, absent, installed, reason in (control, tf):
        assert absent and installed, name
        assert 'is installed but its type support does not load' in reason, reason
    assert 'libcontrol_msgs__rosidl' in control[3]
    assert string == ['std_msgs/msg/String', False, False, '']


@needs_built
def test_a_launcher_started_from_another_venv_runs_its_own(tmp_path):
    """Started with another venv's library path and start-up marker, the run is clean.

    The bridge serves the trajectory action and the state publisher publishes /tf: their
    packages load from the launcher's own venv.
    """
    out = tmp_path / 'run'
    proc = subprocess.run(
        [sys.executable, str(LAUNCHER), '--mode', 'idle', '--duration', '2', '--rtf', '0',
         '--tf', '--no-plots', '--output', str(out)], cwd=ROOT,
        env=foreign_environment(tmp_path), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_reason'] == 'duration reached'
    assert summary['sim_seconds'] >= 2.0 - 1e-6  # the bridge reached sim time
    bridge = (out / 'logs' / 'pybullet_bridge.log').read_text()
    assert 'control_msgs' not in bridge, bridge[-3000:]  # no warning: the action is served
    tf = (out / 'logs' / 'state_publisher.log').read_text()
    assert 'publishing /tf for 6 joints' in tf, tf[-3000:]
