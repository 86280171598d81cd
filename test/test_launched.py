"""The benchmark's launcher runs: each in a ROS domain no other run on this host holds."""
import fcntl
import os
import tempfile

import pytest

from benchmarks import launched


def lock(path):
    """Take ``path``'s lock as another process would (a file of its own); return the file."""
    f = open(path, 'w')
    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return f


def test_a_domain_held_by_another_run_is_skipped_and_a_run_keeps_one_at_a_time(
        tmp_path, monkeypatch):
    """Another holder of 140 + k sends the run on to the next free domain; moving on frees it."""
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp_path))
    monkeypatch.setenv('ROS_DOMAIN_ID', '7')
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET')
    with lock(tmp_path / 'scara_collab_domain_141.lock'):  # a second benchmark, in 141
        assert launched.use_domain(0) == 140
        assert os.environ['ROS_DOMAIN_ID'] == '140'
        assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
        assert launched.use_domain(1) == 142
        assert launched.use_domain(90) == 140  # wraps round; 140 was let go by the move on
    with pytest.raises(OSError):  # this run holds 140 ...
        lock(tmp_path / 'scara_collab_domain_140.lock')
    assert launched.use_domain(5) == 145
    lock(tmp_path / 'scara_collab_domain_140.lock').close()  # ... until it moves on
    launched._HELD.pop().close()


def test_every_domain_held_is_an_error_not_a_shared_domain(tmp_path, monkeypatch):
    """With 140..229 all held elsewhere the run refuses rather than join somebody's graph."""
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp_path))
    monkeypatch.setenv('ROS_DOMAIN_ID', '7')
    others = [lock(tmp_path / f'scara_collab_domain_{d}.lock') for d in range(140, 230)]
    try:
        with pytest.raises(RuntimeError, match='all held'):
            launched.use_domain(3)
        assert os.environ['ROS_DOMAIN_ID'] == '7'
    finally:
        for f in others:
            f.close()
