"""Foreign clocks and second graphs (records.graph_watch): named once per change, with when."""
from scara_collab.records.graph_watch import full_name, GraphWatch, KEEP_JUMPS

CELL = ['/pybullet_bridge', '/left_planner', '/automation_manager', '/run_recorder']


def test_a_second_clock_is_named_once_per_change():
    """Each new set of /clock publishers (more than one) is one entry: when, how many, who."""
    watch = GraphWatch(['pybullet_bridge', 'automation_manager', 'run_recorder'])
    watch.look(0.0, 1.0, [], CELL)                         # before the bridge is up
    watch.look(1.0, 2.0, ['/pybullet_bridge'], CELL)
    for k in range(3):                                     # seen three times: named once
        watch.look(4.0 + k, 5.0 + k, ['/pybullet_bridge', '/rosbag2_player'], CELL)
    watch.look(8.0, 9.0, ['/pybullet_bridge'], CELL)       # gone
    watch.look(9.0, 10.0, ['/pybullet_bridge', '/rosbag2_player'], CELL)  # back: again
    watch.look(10.0, 11.0, ['/pybullet_bridge', '/a', '/b'], CELL)
    summary = watch.summary()
    assert [(c['time'], c['wall_s'], c['publishers'], c['nodes'])
            for c in summary['foreign_clocks']] == [
        (4.0, 5.0, 2, ['/pybullet_bridge', '/rosbag2_player']),
        (9.0, 10.0, 2, ['/pybullet_bridge', '/rosbag2_player']),
        (10.0, 11.0, 3, ['/a', '/b', '/pybullet_bridge'])]
    assert summary['second_graphs'] == [] and summary['graph_looks'] == 8


def test_a_second_graph_is_two_nodes_of_one_name():
    """Two bridges (or two of any of the run's nodes) are a second graph; other names are not."""
    watch = GraphWatch(['pybullet_bridge', 'automation_manager'])
    watch.look(0.0, 1.0, [], CELL + ['/probe', '/probe', '/ns/pybullet_bridge'])
    assert watch.summary()['second_graphs'] == []
    twice = CELL + CELL
    watch.look(0.0, 3.5, ['/pybullet_bridge', '/pybullet_bridge'], twice)
    watch.look(0.5, 4.5, ['/pybullet_bridge', '/pybullet_bridge'], twice)
    summary = watch.summary()
    assert summary['second_graphs'] == [
        {'time': 0.0, 'wall_s': 3.5, 'nodes': {'/automation_manager': 2,
                                               '/pybullet_bridge': 2}}]
    assert summary['foreign_clocks'][0]['nodes'] == ['/pybullet_bridge', '/pybullet_bridge']


def test_backward_jumps_are_counted_and_the_first_kept():
    """Every backward jump of the clock counts; the first few are kept with their times."""
    watch = GraphWatch([])
    for k in range(KEEP_JUMPS + 5):
        watch.clock_back(10.0 + k, 0.5)
    summary = watch.summary()
    assert summary['clock_jumps_back_count'] == KEEP_JUMPS + 5
    assert len(summary['clock_jumps_back']) == KEEP_JUMPS
    assert summary['clock_jumps_back'][0] == {'time': 10.0, 'to': 0.5}
    assert full_name('/', 'a') == '/a' and full_name('/ns', 'a') == '/ns/a'


def test_a_publisher_named_a_moment_late_is_one_foreign_clock():
    """A publisher the middleware knows before its node is the same one when its name comes.

    The entry takes the name; the node leaving before its publisher is no new entry either.
    """
    unknown = '/_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_'
    watch = GraphWatch([])
    watch.look(1.0, 1.0, ['/pybullet_bridge', unknown], CELL)
    watch.look(2.0, 2.0, ['/pybullet_bridge', '/rogue_clock'], CELL)
    watch.look(3.0, 3.0, ['/pybullet_bridge', unknown], CELL)    # its node left first
    watch.look(4.0, 4.0, ['/pybullet_bridge', '/player'], CELL)   # another one: an entry
    assert [(c['time'], c['nodes']) for c in watch.summary()['foreign_clocks']] == [
        (1.0, ['/pybullet_bridge', '/rogue_clock']),
        (4.0, ['/player', '/pybullet_bridge'])]
