"""The launcher's side of the ROS graph: waits, service calls, parameters, readiness checks.

Every wait spins the launcher's executor (the run recorder's) and has a timeout that ends the
run with an error naming what did not come (:class:`~scara_collab.run.supervisor.RunEnd`);
while it waits, the launcher's supervision runs (``check``: signals, dead node processes,
silent nodes). Names are relative to the cell's namespace (:func:`scara_collab.graph.resolve`):
``call(Trigger, 'sim/resume', ...)`` calls this cell's bridge.
"""
import time
from typing import Callable, Dict, List, Optional
import urllib.request

from rclpy.executors import Executor
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_srvs.srv import SetBool, Trigger

from scara_collab import graph
from scara_collab.run.console import Console
from scara_collab.run.stages import Stage
from scara_collab.run.supervisor import RunEnd

SERVICE_TYPES = {'std_srvs/srv/SetBool': SetBool, 'std_srvs/srv/Trigger': Trigger}


def http_ok(url: str, timeout: float = 0.5) -> bool:
    """Return ``True`` if ``url`` answers HTTP 200 (directly: no proxy from the environment)."""
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=timeout) as res:
            return res.status == 200
    except (OSError, ValueError):
        return False


def take(future, answers: list) -> None:
    """Append ``future``'s response to ``answers``; a failed or cancelled call adds nothing."""
    try:
        response = future.result()
    except Exception:  # noqa: B902 - a failed call is a lost answer: asked again
        return
    if response is not None:
        answers.append(response)


class GraphClient:
    """Ask the graph from the launcher's node: wait, call, set parameters, check readiness.

    :param node: the launcher's node (the run recorder): clients and graph queries.
    :param executor: the executor that spins ``node``.
    :param console: where the "asking again" lines go.
    :param check: the supervision run while waiting; raises
        :class:`~scara_collab.run.supervisor.RunEnd` to end the run.
    :param signals: the signals the launcher got so far (a second one ends any wait).
    :param timeout: the default wall seconds of a wait (``--ready-timeout``).
    :param namespace: the cell's namespace (default: the root).
    """

    def __init__(self, node: Node, executor: Executor, console: Console,
                 check: Callable[[], None], signals: List[str], timeout: float,
                 namespace: str = ''):
        """Keep what the waits and calls need; no client is created yet."""
        self.namespace = graph.namespace_of(namespace)
        self.node = node
        self.executor = executor
        self.console = console
        self.check = check
        self.signals = signals
        self.timeout = timeout
        self._clients: Dict[str, object] = {}
        self._bridge_params: Optional[AsyncParameterClient] = None

    # --- waits -----------------------------------------------------------------------------
    def wait_until(self, predicate: Callable[[], bool], timeout: float,
                   on_timeout: Callable[[], str], supervise: bool = True) -> None:
        """Spin the recorder until ``predicate()``; :class:`RunEnd` on timeout or trouble.

        :param supervise: also end on a signal or a dead node (``check``); without it (the
            shutdown) only a second signal cuts the wait short.
        """
        deadline = time.monotonic() + timeout
        while not predicate():
            if supervise:
                self.check()
            elif len(self.signals) > 1:
                raise RunEnd(self.signals[-1], 130)
            if time.monotonic() >= deadline:
                raise RunEnd(on_timeout())
            self.executor.spin_once(timeout_sec=0.02)

    def pause(self, seconds: float) -> None:
        """Spin the recorder for ``seconds`` (wall), supervising; never a timeout of its own.

        (A deadline just beyond the pause would fire whenever a busy machine deschedules the
        launcher for longer than the difference.)
        """
        until = time.monotonic() + seconds
        while time.monotonic() < until:
            self.check()
            self.executor.spin_once(timeout_sec=min(0.02, max(until - time.monotonic(), 0.0)))

    # --- services and parameters -----------------------------------------------------------
    def client(self, srv_type, name: str):
        """Return the client of service ``name`` (in the cell), created on first use."""
        name = graph.resolve(name, self.namespace)
        if name not in self._clients:
            self._clients[name] = self.node.create_client(srv_type, name)
        return self._clients[name]

    def call(self, srv_type, name: str, request, timeout: float, what: str,
             supervise: bool = True, attempts: int = 4, attempt_timeout: float = 5.0):
        """Call a service and return the response, repeating a request whose answer is lost.

        Waits for the service first, then sends the request up to ``attempts`` times,
        ``attempt_timeout`` wall seconds apart.

        A response can be lost (Fast DDS drops one whose client reader is not matched yet),
        so the request is repeated; the servers are idempotent, so a repeat is safe.
        """
        cli = self.client(srv_type, name)
        name = cli.srv_name
        self.wait_until(cli.service_is_ready, timeout,
                        lambda: f'{what}: service {name} not available after {timeout:g} s',
                        supervise)
        for attempt in range(1, attempts + 1):
            answer: list = []
            cli.call_async(request).add_done_callback(lambda f: take(f, answer))
            try:
                self.wait_until(lambda: bool(answer), attempt_timeout, lambda: '', supervise)
            except RunEnd as exc:
                if exc.reason or attempt == attempts:
                    if not exc.reason:
                        raise RunEnd(f'{what}: {name} did not answer {attempts} requests, '
                                     f'{attempt_timeout:g} s apart') from None
                    raise
                self.console.say(f'[launch] {name}: no answer in {attempt_timeout:g} s; '
                                 f'asking again ({attempt + 1}/{attempts})')
                continue
            return answer[0]

    def start(self, name: str, timeout: float, what: str) -> None:
        """Call the start service ``name`` (Trigger) until it succeeds, 0.5 s apart.

        A server may refuse while its own endpoints are not matched yet (DDS discovery).

        :raises RunEnd: it still refused after ``timeout``, with its last word.
        """
        deadline = time.monotonic() + timeout
        while True:
            res = self.call(Trigger, name, Trigger.Request(), timeout, what)
            if res.success:
                return
            if time.monotonic() > deadline:
                raise RunEnd(f'{what} refused to start for {timeout:g} s: {res.message}')
            self.console.say(f'[launch] {what}: {res.message}; asking again')
            self.pause(0.5)

    def set_bridge(self, timeout: Optional[float] = None, supervise: bool = True,
                   **values: float) -> None:
        """Set the bridge's dynamic parameters (``real_time_factor``, ``feed_interval``)."""
        timeout = timeout or self.timeout
        if self._bridge_params is None:
            self._bridge_params = AsyncParameterClient(
                self.node, graph.resolve('pybullet_bridge', self.namespace))
        client = self._bridge_params
        self.wait_until(client.services_are_ready, timeout,
                        lambda: f'pybullet_bridge parameter services not available after '
                        f'{timeout:g} s', supervise)
        future = client.set_parameters(
            [Parameter(k, Parameter.Type.DOUBLE, float(v)) for k, v in values.items()])
        self.wait_until(future.done, timeout, lambda: 'pybullet_bridge did not answer '
                        f'set_parameters within {timeout:g} s', supervise)
        results = future.result().results if future.result() is not None else []
        for (key, value), res in zip(values.items(), results):
            if not res.successful:
                raise RunEnd(f'pybullet_bridge refused {key} {value}: {res.reason}')
        if len(results) != len(values):
            raise RunEnd(f'pybullet_bridge did not set {sorted(values)}')

    # --- the graph -------------------------------------------------------------------------
    def duplicates(self, name: str) -> int:
        """Return how many nodes called ``name`` (in the cell's namespace) are on the graph."""
        here = self.namespace or '/'
        return sum(1 for n, ns in self.node.get_node_names_and_namespaces()
                   if n == name and ns == here)

    def _has(self, node_name: str, topic: str, kind: str) -> bool:
        """Return True if ``node_name`` has a ``kind`` (publisher, subscriber) on ``topic``."""
        query = {'publisher': self.node.get_publisher_names_and_types_by_node,
                 'subscriber': self.node.get_subscriber_names_and_types_by_node}[kind]
        try:
            return any(name == topic for name, _ in query(node_name, self.namespace or '/'))
        except NodeNameNonExistentError:
            return False

    def ready_check(self, stage: Stage) -> Callable[[], bool]:
        """Return the readiness predicate of a stage (from :mod:`scara_collab.graph`)."""
        name, ready = stage.name, graph.node(stage.name).ready
        topic = graph.resolve(ready.name, self.namespace)
        if ready.kind == 'subscribed':
            return lambda: self._has(name, topic, 'subscriber')
        if ready.kind == 'published':
            return lambda: self._has(name, topic, 'publisher')
        if ready.kind == 'service':
            return self.client(SERVICE_TYPES[ready.srv_type], topic).service_is_ready
        if ready.kind == 'page':  # on the graph, and its page answers
            url = f'http://127.0.0.1:{stage.params["port"]}/'
            return lambda: self._has(name, topic, 'subscriber') and http_ok(url)
        raise ValueError(f'no readiness check of kind {ready.kind!r} ({name})')
