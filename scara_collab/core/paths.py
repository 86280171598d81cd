"""Locate the package's share files (``urdf/``, ``config/``) from a checkout or an install."""
from functools import lru_cache
import os
from pathlib import Path
import sys

PACKAGE = 'scara_collab'
_ENV = 'SCARA_COLLAB_SHARE'


def _candidates():
    env = os.environ.get(_ENV)
    if env:
        yield Path(env)
    # A source checkout or an editable install: the repository root holds urdf/ and config/.
    yield Path(__file__).resolve().parents[2]
    # pip install puts data_files under <prefix>/share/<package>.
    yield Path(sys.prefix) / 'share' / PACKAGE
    try:  # a colcon workspace / ROS install
        from ament_index_python.packages import get_package_share_directory
        yield Path(get_package_share_directory(PACKAGE))
    except Exception:  # noqa: BLE001 - ament index missing or package not registered
        return


@lru_cache(maxsize=None)
def share_dir() -> Path:
    """Return the directory holding ``urdf/`` and ``config/``.

    Order: ``$SCARA_COLLAB_SHARE``, the source tree, ``<sys.prefix>/share/scara_collab``,
    the ament index.

    :raises FileNotFoundError: if none of them holds both folders.
    """
    tried = []
    for cand in _candidates():
        tried.append(str(cand))
        if (cand / 'urdf' / 'scara_cell.urdf.xacro').is_file() and (cand / 'config').is_dir():
            return cand
    raise FileNotFoundError(
        f'cannot find the {PACKAGE} share files (urdf/, config/); looked in: '
        + ', '.join(tried) + f'. Set {_ENV} to the folder that holds them.')


def urdf_dir() -> Path:
    """Return the folder of the xacro files."""
    return share_dir() / 'urdf'


def config_dir() -> Path:
    """Return the folder of the default ``*.yaml`` configuration."""
    return share_dir() / 'config'
