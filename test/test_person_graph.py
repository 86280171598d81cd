"""The whole cell in one process with a person walking in beside an arm and out again.

The bridge simulates the person and the scanners, the separation monitor slows the arm near
the person from the scans alone, the job keeps sorting: the person is never within an arm's
protective separation while it moves (ground truth), never touched, and once they have left,
both arms run at full speed again and the job sorts on.
"""
import math

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from sensor_msgs.msg import JointState
import yaml

from scara_collab import graph
from scara_collab.nodes import conversions as conv, protocol as proto
from scara_collab.nodes.runner import InProcess

DURATION = 36.0
#: walks in beside the left arm's outer bin, stands 6 s, walks out the way it came
VISIT = {'visits': [{'start': 4.0, 'speed': 1.4, 'waypoints': [
    [4.5, -6.5], {'x': 4.2, 'y': -3.6, 'dwell': 6.0}, [4.5, -6.5]]}]}


@pytest.fixture(scope='module', params=graph.MONITOR_LINKS)
def run(request, tmp_path_factory):
    """Run the collaborative job for 36 sim s with the person; return what was heard.

    Once with the separation monitor wired into the bridge's process, once as a node of its own
    over topics.
    """
    path = tmp_path_factory.mktemp('person') / 'visit.yaml'
    path.write_text(yaml.safe_dump(VISIT))
    link = request.param
    specs = graph.job_nodes(people=True, monitor_link=link)
    params = graph.job_params('collaborative')
    for name, values in graph.person_params(str(path), 1, link).items():
        params[name].update(values)
    params['pybullet_bridge'].update(real_time_factor=0.0, item_seed=7,
                                     lockstep_expect=graph.lockstep_expect(specs))
    params['automation_manager']['auto_start'] = 'true'
    heard = {'truth': [], 'status': [], 'clock': [], 'safety': [], 'planned': [], 'states': {}}
    with InProcess() as g:
        nodes = {s.name: g.add(s.build(context=g.context, cli_args=graph.ros_args(
            s.configs, params[s.name]))) for s in specs}
        probe = g.probe('person_graph_probe')
        probe.create_subscription(DiagnosticStatus, 'person/truth', lambda m: heard['truth']
                                  .append(proto.PersonTruth.from_msg(m)), 100)
        probe.create_subscription(DiagnosticStatus, 'separation_monitor/status', lambda m:
                                  heard['status'].append(proto.SeparationStatus.from_msg(m)),
                                  100)
        probe.create_subscription(DiagnosticStatus, 'scara_left/trajectory_clock', lambda m:
                                  heard['clock'].append(proto.TrajectoryClock.from_msg(m)), 100)
        probe.create_subscription(JointState, 'safety_joint_states',
                                  lambda m: heard['safety'].append(m), 100)
        probe.create_subscription(JointState, 'planned_velocity',
                                  lambda m: heard['planned'].append(m), 100)
        probe.create_subscription(JointState, 'joint_states', lambda m: heard['states'].update(
            {conv.to_sec(m.header.stamp): m}), 1000)
        bridge = nodes['pybullet_bridge']
        sorted_at = []
        while bridge.sim.time < DURATION:
            g.spin_once(timeout_sec=0.01)
            n = nodes['automation_manager'].job.counts.get('sorted', 0)
            if n > len(sorted_at):
                sorted_at.append(bridge.sim.time)
        heard['sorted_at'] = sorted_at
        heard['missed'] = nodes['automation_manager'].job.counts.get('missed', 0)
        heard['guard'] = nodes['collision_monitor'].status()
        heard['link'] = link
        heard['wired'] = bridge.people.monitor
        heard['monitors'] = probe.get_node_names().count('separation_monitor')
        heard['scaling_subscribed'] = bridge.count_subscribers('scara_left/speed_scaling')
        heard['factor'] = (bridge.people.heard['scara_left'], bridge.sim.time)
    return heard


def test_the_arm_near_the_person_slows_and_resumes_and_the_margin_is_kept(run):
    """Seen, slowed (not the far arm's business), back at full speed once the person left."""
    truth, status = run['truth'], run['status']
    present = [t.time for t in truth if t.present]
    assert present and min(present) >= 4.0
    slowed = [s for s in status if s.scale['scara_left'] < 1.0 and not s.fault]
    assert slowed, 'the person beside the left arm never slowed it'
    assert any(s.cause['scara_left'].startswith('person') for s in slowed)  # then it rises
    left_at = max(present)
    after = [s for s in status if s.time > left_at + 1.5]
    assert after and all(s.scale == {'scara_left': 1.0, 'scara_right': 1.0} for s in after)
    for t in truth:  # ground truth, at every scan: never inside S_p while moving, no contact
        for robot, moving in t.moving.items():
            assert not t.contact[robot]
            if moving:
                assert t.margin[robot] >= 0.0, (t.time, robot, t.margin[robot])


def test_the_job_sorts_on_and_the_arms_keep_their_margin(run):
    """Items sorted while the person is there and after; no arm-to-arm stop, margin kept."""
    assert len(run['sorted_at']) >= 6
    assert any(t > max(tt.time for tt in run['truth'] if tt.present) for t in run['sorted_at'])
    guard = run['guard']
    assert guard.emergency == 0 and guard.protective == 0
    assert guard.minimum >= 0.1
    assert math.isfinite(guard.minimum)


def test_the_monitor_is_told_the_arms_state_and_planned_speed_at_each_scan(run):
    """At every scan: the arms' joint state of that instant, and their planned speed ahead.

    The safety state is the bridge's joint state of its instant to the bit; the planned speed
    ahead is now and then faster than the arm moves (an arm about to speed up).
    """
    safety = [conv.to_sec(m.header.stamp) for m in run['safety']]
    planned = [conv.to_sec(m.header.stamp) for m in run['planned']]
    assert safety == planned and len(safety) == pytest.approx(25 * DURATION, abs=2)
    assert all(round(t * 25.0, 6).is_integer() for t in safety)  # once a scan
    compared = ahead = 0
    for m, p in zip(run['safety'], run['planned']):
        state = run['states'].get(conv.to_sec(m.header.stamp))
        if state is None:
            continue
        compared += 1
        assert list(m.name) == list(state.name) == list(p.name)
        assert list(m.position) == list(state.position)
        assert list(m.velocity) == list(state.velocity)
        ahead += bool(np.any(np.abs(p.velocity) > np.abs(m.velocity) + 1e-3))
    assert compared > 20 * DURATION and ahead > 0


def test_what_changes_nothing_is_not_said_again(run):
    """What has not changed is not said again: a cell without a person costs little.

    The bridge says an arm's clock when it changes, the arms' safety state once a scan (not at
    the state rate: the test above), the truth of a person away once a second; the monitor its
    status when it changes.
    """
    clocks = run['clock']
    assert clocks and any(c.scale < 1.0 for c in clocks)
    for a, b in zip(clocks, clocks[1:]):
        assert (a.lag, a.scale, a.target) != (b.lag, b.scale, b.target) or b.held_back
    assert all(c.time < max(t.time for t in run['truth'] if t.present) + 5.0 for c in clocks)
    away = [t.time for t in run['truth'] if not t.present and t.time > 20.0]
    assert away and all(b - a >= 1.0 - 1e-6 for a, b in zip(away, away[1:]))
    quiet = [s.time for s in run['status'] if s.time > 25.0]  # nobody in the cell
    assert quiet and all(b - a >= 1.0 - 1e-6 for a, b in zip(quiet, quiet[1:]))


def test_the_monitor_wired_into_the_bridge_decides_at_the_scan_it_is_handed(run):
    """Wired, the monitor is a node in the bridge's process, and its factors reach no topic.

    One ``separation_monitor`` on the graph either way. Wired: built by the bridge, handed
    each scan and state, its factors handed straight back (the bridge subscribes none; the
    newest was heard within one state step); over topics: a node of its own.
    """
    assert run['monitors'] == 1
    heard, now = run['factor']
    if run['link'] == 'wired':
        assert run['wired'] is not None and run['wired'].wired is not None
        assert run['scaling_subscribed'] == 0
        assert now - heard <= 0.01 + 1e-9
    else:
        assert run['wired'] is None and run['scaling_subscribed'] >= 1
