"""Fast DDS's discovery server on localhost: the wheel's server, its clients, a super client.

The line of cells runs through it end to end in ``test_line.py`` (``--discovery-server``);
here: nodes behind the server are found through it and only through it. Every participant
runs in a process of its own: Fast DDS reads ``ROS_DISCOVERY_SERVER`` once per process, so
one made here would leave this pytest process a client of a server that is gone.
"""
import json
import os
from pathlib import Path
import subprocess
import sys

import pytest

from scara_collab.run import discovery

NODE = ('import sys, time, rclpy\n'
        'rclpy.init()\n'
        'node = rclpy.create_node(sys.argv[1])\n'
        'end = time.monotonic() + 60.0\n'
        'while rclpy.ok() and time.monotonic() < end:\n'
        '    rclpy.spin_once(node, timeout_sec=0.1)\n')
#: a participant that looks for nodes: prints the names it saw, after it saw all of argv[2:]
#: or after argv[1] seconds
LOOK = ('import json, sys, time, rclpy\n'
        'rclpy.init()\n'
        "node = rclpy.create_node('look')\n"
        'want, seen = set(sys.argv[2:]), set()\n'
        'end = time.monotonic() + float(sys.argv[1])\n'
        'while time.monotonic() < end and not want <= seen:\n'
        '    rclpy.spin_once(node, timeout_sec=0.2)\n'
        '    seen |= {n for n, _ in node.get_node_names_and_namespaces()}\n'
        'print(json.dumps(sorted(seen)))\n')


def test_the_servers_command_is_the_wheels_with_its_libraries():
    """The server is the venv's ``fast-discovery-server``; its libraries are on the path."""
    cmd, env = discovery.server_command(11888)
    assert Path(cmd[0]).name == 'fast-discovery-server' and Path(cmd[0]).is_file()
    assert cmd[1:] == ['-i', '0', '-l', '127.0.0.1', '-p', '11888']
    assert any(p.endswith('ros_fastrtps.libs') for p in env['LD_LIBRARY_PATH'].split(':'))


def test_only_the_launcher_is_a_super_client():
    """``super_client`` sets ``ROS_SUPER_CLIENT`` inside only, and only with a server in use."""
    env = {k: os.environ.pop(k) for k in (discovery.ENV, discovery.SUPER) if k in os.environ}
    try:
        with discovery.super_client() as is_super:  # simple discovery: nothing to do
            assert not is_super and discovery.SUPER not in os.environ
        os.environ[discovery.ENV] = '127.0.0.1:11888'
        with discovery.super_client() as is_super:
            assert is_super and os.environ[discovery.SUPER] == 'TRUE'
        assert discovery.SUPER not in os.environ  # the nodes started later: plain clients
        os.environ[discovery.SUPER] = 'FALSE'  # the user's word stands
        with discovery.super_client() as is_super:
            assert not is_super and os.environ[discovery.SUPER] == 'FALSE'
    finally:
        for k in (discovery.ENV, discovery.SUPER):
            os.environ.pop(k, None)
        os.environ.update(env)


def _look(env, timeout, *names):
    out = subprocess.run([sys.executable, '-c', LOOK, str(timeout), *names], env=env,
                         capture_output=True, text=True, timeout=timeout + 60)
    assert out.returncode == 0, out.stderr[-2000:]
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_nodes_behind_a_server_are_found_through_it_and_only_through_it():
    """A client node is seen by a super client of the server, not by simple discovery.

    A node with simple discovery beside it is the control: the simple participant sees that
    one, so not seeing the client is the server's doing, not a deaf participant's.
    """
    plain = {k: v for k, v in os.environ.items() if k not in (discovery.ENV, discovery.SUPER)}
    stamp = f'{os.getpid()}'
    hidden, open_ = f'behind_server_{stamp}', f'simple_{stamp}'
    procs = [subprocess.Popen([sys.executable, '-c', NODE, open_], env=plain)]
    try:
        with discovery.server() as address:
            assert os.environ[discovery.ENV] == address
            client = dict(plain, **{discovery.ENV: address})
            procs.append(subprocess.Popen([sys.executable, '-c', NODE, hidden], env=client))
            seen = _look(dict(client, **{discovery.SUPER: 'TRUE'}), 30.0, hidden)
            assert hidden in seen, f'the super client never saw the client node: {seen}'
            seen = _look(plain, 8.0, open_, hidden)
            assert open_ in seen, f'simple discovery never saw the simple node: {seen}'
            assert hidden not in seen  # discovery went through the server
        assert discovery.ENV not in os.environ
    finally:
        for p in procs:
            p.kill()
            p.wait()


def test_a_taken_port_is_an_error_not_a_silent_simple_discovery():
    """A second server on a port in use exits at once, and the launcher is told why."""
    with discovery.server() as address:
        port = int(address.rsplit(':', 1)[1])
        with pytest.raises(RuntimeError, match='exited at once'):
            with discovery.server(port):
                pass
        assert os.environ[discovery.ENV] == address  # the outer server's, restored
