"""Fast DDS's discovery server for a run: the wheel's server, and the launcher as a super client.

With simple discovery (the default) every participant on the domain meets every other by
multicast. A line of many cells is better served by Fast DDS's discovery server: every
process is its client (``ROS_DISCOVERY_SERVER=HOST:PORT``) and learns only the endpoints it
matches. The ``ros-jazzy-rclpy[fastrtps]`` wheel ships the server as
``<venv>/bin/fast-discovery-server``; it needs the wheel's libraries on ``LD_LIBRARY_PATH``
(:func:`server_command` finds them).

The launcher asks the graph for what it does not subscribe to (which nodes are up, a second
graph on the domain, who publishes ``/clock``). A plain client does not learn that, so the
launcher's own participant is a *super client* (``ROS_SUPER_CLIENT``), which learns the whole
graph from the server; the nodes stay plain clients (:func:`super_client`).

``launch_cell.py --discovery-server [PORT]`` starts a server on this host for the run and
stops it at the end (:func:`server`); with ``ROS_DISCOVERY_SERVER`` already set, the run uses
that server, on this machine or another.
"""
from contextlib import contextmanager
import os
from pathlib import Path
import socket
import subprocess
import sys
import sysconfig
import tempfile
import time
from typing import Dict, Iterator, List, Optional, Tuple

from scara_collab.run.child import die_with_parent

ENV = 'ROS_DISCOVERY_SERVER'
SUPER = 'ROS_SUPER_CLIENT'
SERVER = 'fast-discovery-server'


def server_command(port: int, host: str = '127.0.0.1',
                   server_id: int = 0) -> Tuple[List[str], Dict[str, str]]:
    """Return the command and environment that run the wheel's discovery server.

    :raises FileNotFoundError: if this Python's environment has no ``fast-discovery-server``.
    """
    exe = Path(sys.executable).parent / SERVER
    if not exe.is_file():
        raise FileNotFoundError(f'{exe} not found: the discovery server comes with '
                                'ros-jazzy-rclpy[fastrtps] (./scripts/bootstrap)')
    site = Path(sysconfig.get_paths()['purelib'])
    libs = [str(Path(sys.prefix) / 'lib'), str(site / 'ros_fastrtps.libs'),
            os.environ.get('LD_LIBRARY_PATH', '')]
    env = dict(os.environ, LD_LIBRARY_PATH=os.pathsep.join(p for p in libs if p))
    return [str(exe), '-i', str(server_id), '-l', host, '-p', str(port)], env


def free_port(host: str = '127.0.0.1') -> int:
    """Return a UDP port on ``host`` that nobody uses now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


@contextmanager
def server(port: Optional[int] = None, host: str = '127.0.0.1') -> Iterator[str]:
    """Run a discovery server on ``host`` meanwhile; every process started inside uses it.

    Sets ``ROS_DISCOVERY_SERVER`` in this process's environment, so the processes started
    inside (the nodes, the cells' launchers) are its clients, and restores it after. The
    server dies with this process (SIGTERM on its death). Yields ``HOST:PORT``.

    Fast DDS reads the variable once per process, with its first participant: a process that
    made a participant inside stays a client of this server after it (the launcher makes
    none after the run).

    :param port: UDP port (default: a free one).
    :raises RuntimeError: if the server exits at once (the port is taken, say), with its output.
    """
    port = port or free_port(host)
    cmd, env = server_command(port, host)
    env.pop(ENV, None)
    parent = os.getpid()
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=lambda: die_with_parent(parent))
        before = os.environ.get(ENV)
        try:
            time.sleep(0.3)
            if proc.poll() is not None:
                out.seek(0)
                said = out.read().decode(errors='replace').strip().splitlines()[-3:]
                raise RuntimeError(f'{SERVER} on {host}:{port} exited at once (code '
                                   f'{proc.returncode}): {" / ".join(said) or "no output"}')
            os.environ[ENV] = f'{host}:{port}'
            yield os.environ[ENV]
        finally:
            if before is None:
                os.environ.pop(ENV, None)
            else:
                os.environ[ENV] = before
            proc.terminate()
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@contextmanager
def super_client() -> Iterator[bool]:
    """Make the participants created inside super clients, if a discovery server is in use.

    Wrap ``rclpy.init`` of a process that asks the graph for what it does not subscribe to
    (the launcher). Only this process's participant: the variable is restored after, so the
    nodes it starts later stay plain clients. Yields whether it is one.
    """
    if not os.environ.get(ENV) or SUPER in os.environ:
        yield os.environ.get(SUPER, '').upper() in ('TRUE', '1')
        return
    os.environ[SUPER] = 'TRUE'
    try:
        yield True
    finally:
        os.environ.pop(SUPER, None)
