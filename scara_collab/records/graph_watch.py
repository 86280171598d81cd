"""Who else is on the domain: a second ``/clock``, a clock that jumps back, a second graph.

No rclpy here: the run recorder looks at the graph once a wall second while it records
(:meth:`GraphWatch.look`: the node names of ``/clock``'s publishers and of every node on the
graph) and hands over each backward jump of its sim clock (:meth:`GraphWatch.clock_back`).
The bridge is the run's only clock and each run has one of each of its nodes, so:

- a second ``/clock`` publisher (whoever it is: another bridge, ``ros2 bag play --clock``, a
  test tool) is a *foreign clock*, named with when it was seen, how many publishers there were
  and their nodes, once per change of that set. The middleware can know a publisher a moment
  before it knows its node (and a moment after the node left): its name is then
  ``_NODE_NAME_UNKNOWN_``; such a look is the same set as the look before or after that knows
  the name, and the entry takes the name once it is known;
- sim time that goes backwards is a foreign clock too (the bridge's never does; a clock that
  only repeats the bridge's time is seen as its publisher);
- two nodes of the same name among the cell's (two bridges, two automation managers, two run
  recorders: two launchers on one ``ROS_DOMAIN_ID``) are a *second graph*, named the same way.
  The launcher refuses to start next to a graph that is already there; this catches the one
  that comes later, or at the same moment.

A cell in a namespace has its own clock (``<ns>/clock``) and its nodes' full names are in that
namespace, so another cell under another namespace on the same domain is neither.

>>> watch = GraphWatch(['pybullet_bridge', 'automation_manager'])
>>> watch.look(0.0, 1.0, ['/pybullet_bridge'], ['/pybullet_bridge', '/automation_manager'])
>>> watch.look(4.0, 5.0, ['/pybullet_bridge', '/player'], ['/pybullet_bridge', '/player'])
>>> watch.look(5.0, 6.0, ['/pybullet_bridge', '/player'], ['/pybullet_bridge', '/player'])
>>> [(c['time'], c['publishers'], c['nodes']) for c in watch.summary()['foreign_clocks']]
[(4.0, 2, ['/player', '/pybullet_bridge'])]
>>> cell = GraphWatch(['pybullet_bridge'], namespace='/cell_1')
>>> cell.look(0.0, 1.0, ['/cell_1/pybullet_bridge'], ['/cell_1/pybullet_bridge',
...                                                   '/cell_0/pybullet_bridge'])
>>> cell.summary()['second_graphs'], sorted(cell.names)
([], ['/cell_1/pybullet_bridge'])
"""
from collections import Counter
from typing import Dict, Iterable, List, Optional, Sequence

#: backward jumps kept in the summary (all are counted)
KEEP_JUMPS = 20
#: the node name rmw gives an endpoint whose node it does not know (yet, or any more)
UNNAMED = '_NODE_NAME_UNKNOWN_'


def same_publishers(a: Sequence[str], b: Sequence[str]) -> bool:
    """Return whether two looks at a topic's publishers can be the same set of publishers.

    They are when they count the same and the names one knows are among the other's (a
    publisher whose node is not known yet, or any more, is ``UNNAMED``).

    >>> same_publishers(['/bridge', '/_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_'],
    ...                 ['/bridge', '/rogue'])
    True
    >>> same_publishers(['/bridge', '/rogue'], ['/bridge', '/player'])
    False
    """
    if len(a) != len(b):
        return False
    named_a = Counter(n for n in a if not n.endswith(UNNAMED))
    named_b = Counter(n for n in b if not n.endswith(UNNAMED))
    return not (named_a - named_b) or not (named_b - named_a)


def full_name(namespace: str, name: str) -> str:
    """Return a node's full name: ``('/', 'bridge')`` -> ``'/bridge'``."""
    return namespace.rstrip('/') + '/' + name


class GraphWatch:
    """Foreign clocks and second graphs seen during a run; see the module docstring.

    :param names: the node names a run has one of each (in the cell's namespace), e.g. the
        cell's nodes and the launcher's own.
    :param namespace: the cell's namespace (default: the root).
    """

    def __init__(self, names: Iterable[str], namespace: str = ''):
        """Watch for a second node of any of ``names``; nothing seen yet."""
        self.names = frozenset(full_name(namespace or '/', n.lstrip('/')) for n in names)
        self.foreign_clocks: List[Dict[str, object]] = []
        self.second_graphs: List[Dict[str, object]] = []
        self.jumps: List[Dict[str, float]] = []
        self.jump_count = 0
        self.looks = 0
        self._clocks: Optional[tuple] = None   # the publisher set of the last foreign clock
        self._twins: Optional[tuple] = None    # the duplicates of the last second graph

    def look(self, t: float, wall: float, clock_publishers: Sequence[str],
             nodes: Sequence[str]) -> None:
        """Take one look at the graph.

        :param t: sim time now, s.
        :param wall: wall seconds since the recording began.
        :param clock_publishers: the full node name of each publisher of the cell's clock.
        :param nodes: the full name of each node on the graph (repeats included).
        """
        self.looks += 1
        clocks = tuple(sorted(clock_publishers))
        last = self.foreign_clocks[-1] if self.foreign_clocks else None
        if (len(clocks) > 1 and self._clocks is not None
                and same_publishers(clocks, last['nodes'])):
            unnamed = sum(n.endswith(UNNAMED) for n in clocks)
            if unnamed < sum(n.endswith(UNNAMED) for n in last['nodes']):
                last['nodes'] = list(clocks)           # the same publishers, better named
        elif len(clocks) > 1:
            self.foreign_clocks.append({'time': t, 'wall_s': round(wall, 3),
                                        'publishers': len(clocks), 'nodes': list(clocks)})
        self._clocks = clocks if len(clocks) > 1 else None
        count = Counter(n for n in nodes if n in self.names)
        twins = tuple(sorted((n, c) for n, c in count.items() if c > 1))
        if twins and twins != self._twins:
            self.second_graphs.append({'time': t, 'wall_s': round(wall, 3),
                                       'nodes': dict(twins)})
        self._twins = twins or None

    def clock_back(self, before: float, after: float) -> None:
        """Take a backward jump of the sim clock from ``before`` to ``after`` (sim s)."""
        self.jump_count += 1
        if len(self.jumps) < KEEP_JUMPS:
            self.jumps.append({'time': before, 'to': after})

    def summary(self) -> Dict[str, object]:
        """Return ``foreign_clocks``, ``clock_jumps_back`` (and their count), ``second_graphs``."""
        return {'foreign_clocks': list(self.foreign_clocks),
                'clock_jumps_back': list(self.jumps),
                'clock_jumps_back_count': self.jump_count,
                'second_graphs': list(self.second_graphs),
                'graph_looks': self.looks}
