"""ament_python package setup for scara_collab."""
from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'scara_collab'

# One entry per executable of SPEC section 3; each is added by the change that builds its node.
console_scripts = [
    'pybullet_bridge = scara_collab.nodes.pybullet_bridge:main',
    'left_planner = scara_collab.nodes.planner:main_left',
    'right_planner = scara_collab.nodes.planner:main_right',
    'replication_manager = scara_collab.nodes.replication_manager:main',
    'collision_monitor = scara_collab.nodes.collision_monitor:main',
    'automation_manager = scara_collab.nodes.automation_manager:main',
    'cell_viewer = scara_collab.nodes.cell_viewer:main',
]


def share(subdir: str, pattern: str = '*'):
    """Install ``subdir/pattern`` files under ``share/scara_collab/subdir``."""
    files = [f for f in glob(os.path.join(subdir, pattern)) if os.path.isfile(f)]
    return (os.path.join('share', package_name, subdir), files)


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        share('urdf'),
        share('config', '*.yaml'),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='scara_collab maintainers',
    maintainer_email='maintainers@scara-collab.invalid',
    description='Collaborative dual-SCARA sorting cell on ROS 2 Jazzy with a PyBullet bridge',
    license='Apache-2.0',
    entry_points={'console_scripts': console_scripts},
)
