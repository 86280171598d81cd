"""Shared test setup: DDS isolation for every session, the default cell model, a context."""
import os

import pytest

# Each pytest session talks on its own DDS domain and only on this host, so parallel runs and
# other ROS graphs on the machine never hear each other. Set before rclpy is imported.
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


@pytest.fixture(scope='session')
def cell():
    """Return the default cell model (built once per session)."""
    from scara_collab.core.model import load_cell
    return load_cell()


@pytest.fixture
def context():
    """Yield an initialised rclpy context of its own; shut it down afterwards."""
    import rclpy  # after the DDS settings above
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)
