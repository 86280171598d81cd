"""The bridge's periodic publications stay on their grids however long the run."""
from types import SimpleNamespace

from scara_collab.nodes.bridge_outputs import BridgeOutputs


def test_the_states_stay_on_their_grid_after_an_hour_of_sim_time():
    """The state of every 10 ms goes out at the step of its instant, at 3,600 sim s too.

    The next instant is origin + count x period: a running sum of 0.01 s drifted past the
    1e-9 s the grid is matched within after about 2,170 sim s, and from then on every state
    came one physics step late (a lockstep node waiting for the state of its instant then
    waited out its reply deadline at every tick).
    """
    out = object.__new__(BridgeOutputs)  # the grid logic alone: no node, no publishers
    dt, steps = 0.001, [0]
    out.sim = SimpleNamespace(time=0.0)
    out.periods = {'state': 0.01, 'clock': 0.02, 'markers': 1e9, 'diagnostics': 1e9}
    out.next = {k: 0.0 for k in out.periods}
    out._origin = {k: 0.0 for k in out.periods}
    out._count = {k: 0 for k in out.periods}
    out._added, out._first = [], []
    late = []
    out.state = lambda: steps[0] % 10 == 0 or late.append(steps[0])
    out.clock, out._on_clock = (lambda: None), (lambda: None)
    out.diagnostics = SimpleNamespace(publish=lambda msg: None)
    out._status = lambda: None
    out.items_pub = SimpleNamespace(publish=lambda msg: None)
    out.sim.conveyor = SimpleNamespace(items=lambda: [])
    out.cell = SimpleNamespace(item_classes=[], item_size=0.1)
    out.publish_all()  # as the bridge does when it starts
    while steps[0] < 3_600_000:
        steps[0] += out.steps_to_next(dt)
        out.sim.time = steps[0] * dt
        out.publish_due()
    assert late == []
