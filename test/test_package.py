"""The package builds the ROS way: colcon build in a fresh workspace puts files where ROS looks."""
import configparser
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).parent / 'colcon'


def _console_scripts():
    """Return the executables ``ros2 run`` must find: one per node of the graph."""
    from scara_collab import graph
    return [n.name for n in graph.NODES]


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """Build the package with colcon in a fresh workspace once; return its install prefix."""
    if not COLCON.exists():
        pytest.fail(f'colcon is not installed next to {sys.executable}; run ./scripts/bootstrap')
    ws = tmp_path_factory.mktemp('ws')
    ignore = shutil.ignore_patterns('.venv', '.git', 'build', 'install', 'log', 'runs',
                                    '__pycache__', '*.egg-info', '.pytest_cache', '.hypothesis')
    shutil.copytree(ROOT, ws / 'src' / 'scara_collab', ignore=ignore)
    env = dict(os.environ, PATH=f'{COLCON.parent}{os.pathsep}{os.environ["PATH"]}')
    proc = subprocess.run([str(COLCON), 'build', '--event-handlers', 'console_direct-'],
                          cwd=ws, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / 'install' / 'scara_collab'


def test_colcon_installs_share_files_and_marker(installed):
    """A colcon build installs the marker, package.xml, xacro, configs and Python package."""
    share = installed / 'share' / 'scara_collab'
    assert (installed / 'share/ament_index/resource_index/packages/scara_collab').is_file()
    assert (share / 'package.xml').is_file()
    for name in ('scara_arm.xacro', 'scara_arm.urdf.xacro', 'scara_cell.urdf.xacro'):
        assert (share / 'urdf' / name).is_file()
    for name in ('cell', 'simulation', 'controllers', 'automation'):
        assert (share / 'config' / f'{name}.yaml').is_file()
    assert (share / 'launch' / 'cell.launch.py').is_file()  # ros2 launch scara_collab ...
    assert (share / 'config' / 'cell.rviz').is_file()
    site = list(installed.glob('lib/python3*/site-packages/scara_collab/core/model.py'))
    assert site, 'the Python package is installed into the workspace'
    extra = [p.name for p in site[0].parents[2].iterdir()
             if p.is_dir() and (p / '__init__.py').is_file() and p.name != 'scara_collab']
    assert not extra, f'packages installed beside scara_collab: {extra}'


def test_colcon_installs_every_executable_under_lib(installed):
    """Every console script is installed as an executable under ``lib/scara_collab``."""
    for name in _console_scripts():
        exe = installed / 'lib' / 'scara_collab' / name
        assert exe.is_file() and os.access(exe, os.X_OK), f'ros2 run cannot find {name}'


def test_setup_cfg_puts_scripts_where_ros2_run_looks():
    """setup.cfg puts the scripts in ``$base/lib/scara_collab``, where ``ros2 run`` looks."""
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / 'setup.cfg')
    assert cfg['develop']['script_dir'] == '$base/lib/scara_collab'
    assert cfg['install']['install_scripts'] == '$base/lib/scara_collab'


def test_xacro_expands_from_the_installed_share_directory(installed):
    """The cell xacro expands from the installed share folder (4 revolute, 2 prismatic)."""
    import xacro
    share = installed / 'share' / 'scara_collab'
    xml = xacro.process_file(str(share / 'urdf' / 'scara_cell.urdf.xacro')).toxml()
    assert xml.count('type="revolute"') == 4 and xml.count('type="prismatic"') == 2


def test_package_xml_declares_what_the_code_imports():
    """package.xml declares every ROS package, numpy, yaml and xacro the code imports."""
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('export/build_type') == 'ament_python'
    declared = {e.text for e in root if e.tag.endswith('depend')}
    imported = set()
    for py in (ROOT / 'scara_collab').rglob('*.py'):
        for m in re.finditer(r'^\s*(?:from|import)\s+(\w+)', py.read_text(), re.M):
            imported.add(m.group(1))
    ros = {m for m in imported if m == 'rclpy' or m.endswith('_msgs') or m == 'std_srvs'}
    assert ros <= declared, f'undeclared ROS dependencies: {sorted(ros - declared)}'
    for name in ('numpy', 'yaml'):
        if name in imported:
            assert f'python3-{name}' in declared
    if 'xacro' in imported:
        assert 'xacro' in declared


def test_rclpy_stays_in_the_node_and_process_layers():
    """Only ``nodes/`` and ``run/`` import rclpy; core imports nothing above.

    The layers of docs/design.md's *Architecture*: core (numpy), sim (PyBullet) and records
    (files, figures) run no ROS node of their own. The benchmarks (``benchmarks/``, beside the
    package and not installed) are outside these layers: their probe is a node of its own.
    """
    ros = re.compile(r'^\s*(?:from|import)\s+rclpy\b', re.M)
    package = ROOT / 'scara_collab'
    offenders = [str(py.relative_to(ROOT)) for py in package.rglob('*.py')
                 if py.parent.name not in ('nodes', 'run') and ros.search(py.read_text())]
    assert not offenders, f'rclpy imported outside nodes/ and run/: {offenders}'
    upward = re.compile(r'^\s*(?:from|import)\s+scara_collab\.(?!core\b)', re.M)
    core = [str(py.relative_to(ROOT)) for py in (package / 'core').rglob('*.py')
            if upward.search(py.read_text())]
    assert not core, f'core imports from a layer above it: {core}'
