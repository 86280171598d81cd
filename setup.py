"""ament_python package setup for scara_collab."""
from glob import glob
import importlib.util
import os
import sys

from setuptools import find_packages, setup

package_name = 'scara_collab'


def node_executables():
    """Return the console scripts: one per node of ``scara_collab/graph.py``, named like it.

    The graph's description is read alone (it needs only the standard library), so the
    package need not be importable while it is being built.
    """
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), package_name, 'graph.py')
    spec = importlib.util.spec_from_file_location('_scara_collab_graph', path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being built
    spec.loader.exec_module(module)
    return module.console_scripts()


def share(subdir: str, pattern: str = '*'):
    """Install ``subdir/pattern`` files under ``share/scara_collab/subdir``."""
    files = [f for f in glob(os.path.join(subdir, pattern)) if os.path.isfile(f)]
    return (os.path.join('share', package_name, subdir), files)


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=[package_name, package_name + '.*']),  # not benchmarks/
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        share('urdf'),
        share('config', '*.yaml'),
        share('config', '*.rviz'),
        share('launch', '*.launch.py'),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='scara_collab maintainers',
    maintainer_email='maintainers@scara-collab.invalid',
    description='Collaborative dual-SCARA sorting cell on ROS 2 Jazzy with a PyBullet bridge',
    license='Apache-2.0',
    entry_points={'console_scripts': node_executables()},
)
