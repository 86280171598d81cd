"""Fast DDS's discovery server on localhost: the wheel's server, its clients, a super client.

The line of cells runs through it end to end in ``test_line.py`` (``--discovery-server``);
here: nodes behind the server are found through it and only through it.
"""
import os
from pathlib import Path
import subprocess
import sys
import time

import pytest

from scara_collab.run import discovery

NODE = ('import sys, time, rclpy\n'
        'rclpy.init()\n'
        'node = rclpy.create_node(sys.argv[1])\n'
        'end = time.monotonic() + 60.0\n'
        'while rclpy.ok() and time.monotonic() < end:\n'
        '    rclpy.spin_once(node, timeout_sec=0.1)\n')


def test_the_servers_command_is_the_wheels_with_its_libraries():
    """The server is the venv's ``fast-discovery-server``; its libraries are on the path."""
    cmd, env = discovery.server_command(11888)
    assert Path(cmd[0]).name == 'fast-discovery-server' and Path(cmd[0]).is_file()
    assert cmd[1:] == ['-i', '0', '-l', '127.0.0.1', '-p', '11888']
    assert any(p.endswith('ros_fastrtps.libs') for p in env['LD_LIBRARY_PATH'].split(':'))


def _names(node):
    return {n for n, _ in node.get_node_names_and_namespaces()}


def _participant(name: str):
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    return ctx, rclpy.create_node(name, context=ctx)


def test_nodes_behind_a_server_are_found_through_it_and_only_through_it():
    """A client node is seen by a super client of the server, not by simple discovery.

    A node with simple discovery beside it is the control: the simple participant sees that
    one, so not seeing the client is the server's doing, not a deaf participant's.
    """
    import rclpy
    env = dict(os.environ)
    env.pop(discovery.ENV, None)
    stamp = f'{os.getpid()}_{int(time.monotonic() * 1000) % 100000}'
    hidden, open_ = f'behind_server_{stamp}', f'simple_{stamp}'
    procs, made = [], []
    try:
        procs.append(subprocess.Popen([sys.executable, '-c', NODE, open_], env=env))
        plain = _participant(f'look_simple_{stamp}')  # before the server: simple discovery
        made.append(plain)
        with discovery.server() as address:
            assert os.environ[discovery.ENV] == address
            procs.append(subprocess.Popen([sys.executable, '-c', NODE, hidden],
                                          env=dict(env, **{discovery.ENV: address})))
            with discovery.super_client() as is_super:
                assert is_super and os.environ[discovery.SUPER] == 'TRUE'
                made.append(_participant(f'look_super_{stamp}'))
            assert discovery.SUPER not in os.environ  # the nodes started later: plain clients
            end = time.monotonic() + 20.0
            while time.monotonic() < end and not (hidden in _names(made[1][1])
                                                  and open_ in _names(plain[1])):
                time.sleep(0.2)
            assert hidden in _names(made[1][1]), 'the super client never saw the client node'
            assert open_ in _names(plain[1]), 'simple discovery never saw the simple node'
            time.sleep(2.0)
            assert hidden not in _names(plain[1])  # discovery went through the server
        assert discovery.ENV not in os.environ
    finally:
        for p in procs:
            p.kill()
            p.wait()
        for ctx, node in made:
            node.destroy_node()
            rclpy.try_shutdown(context=ctx)


def test_a_taken_port_is_an_error_not_a_silent_simple_discovery():
    """A second server on a port in use exits at once, and the launcher is told why."""
    with discovery.server() as address:
        port = int(address.rsplit(':', 1)[1])
        with pytest.raises(RuntimeError, match='exited at once'):
            with discovery.server(port):
                pass
        assert os.environ[discovery.ENV] == address  # the outer server's, restored
