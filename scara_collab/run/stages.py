"""The launcher's processes, planned from :mod:`scara_collab.graph`: one stage per node.

A :class:`Stage` is one node process with its parameters and its command line
(``python -m scara_collab.run.child <module>:<function> --ros-args ...``); with
``--one-process`` one stage runs them all (:func:`one_process`, ``python -m
scara_collab.run.container --node ... --node ...``). With ``--namespace`` every node runs in
the cell's namespace with the cell's remaps (:func:`scara_collab.graph.ros_args`); a cell of a
line of cells (``--line-cell K`` of ``--cells N``) also gets its bridge's line parameters and
its upstream cell's handoff topic (:func:`scara_collab.graph.line_params`). With ``--person``
(in this cell) the bridge gets the person's scenario and its seed and runs the separation
monitor in its process; with ``--monitor-link topics`` the monitor runs as a node of its own
after the bridge, among the bridge's guards (:func:`scara_collab.graph.person_params`).

With ``--fault`` each node process gets the entries the nodes apply (``--fault SPEC`` after
the entry: :mod:`scara_collab.run.child`, :mod:`scara_collab.run.container`); a crash is the
supervisor's (:func:`crashes`), and one that names the bridge also makes it pause at that sim
time (its ``pause_at``), so the supervisor kills it there to the physics step.
"""
from dataclasses import dataclass, field
from pathlib import Path
import sys
from typing import Dict, List, Sequence, Tuple

from scara_collab import graph
from scara_collab.run.options import LaunchOptions

CONTAINER = 'cell'  # --one-process: the one process's name (logs/cell.log)


@dataclass
class Stage:
    """One node process of the graph and what "ready" means for it."""

    name: str                   # node name = log file name
    entry: str                  # module:function
    configs: Tuple[str, ...]    # config/<name>.yaml files passed with --params-file
    ready: str                  # what the launcher waits for, for messages
    params: Dict[str, str] = field(default_factory=dict)
    members: Tuple['Stage', ...] = ()  # --one-process: the stages this process runs
    namespace: str = ''         # the cell's namespace ('' = the root)
    upstream: Tuple[str, ...] = ()  # in a line: the cells upstream, nearest first
    faults: Tuple[str, ...] = ()  # --fault entries its nodes apply (not the crashes)


def stages(opts: LaunchOptions, with_automation: bool) -> List[Stage]:
    """Return the graph for ``opts``, in launch order (the nodes of :mod:`scara_collab.graph`)."""
    common = {} if opts.profile is None else {'profile': opts.profile}
    by_mode = graph.job_params(opts.mode, opts.lockstep)
    port = opts.viewer
    person = opts.cell_person
    specs = graph.job_nodes(automation=with_automation, viewer=port is not None,
                            transforms=opts.tf, people=person is not None,
                            monitor_link=opts.monitor_link)
    own: Dict[str, Dict[str, str]] = {
        # paused until the job has started (Launcher.start_job), so every run starts at sim
        # time 0 with every node there; the belt feeds from then on
        'pybullet_bridge': {'real_time_factor': repr(float(opts.launch_rtf)),
                            'feed_interval': '0.0', 'paused': 'true',
                            # the job window ends at sim t=duration exactly (it starts at 0)
                            'pause_at': repr(float(opts.duration)),
                            'lockstep_expect': graph.param_value(graph.lockstep_expect(specs))},
        'automation_manager': {'auto_start': 'false'},  # the launcher starts the job
    }
    bridge = own['pybullet_bridge']
    if opts.step_chunk is not None:
        bridge['step_chunk'] = repr(float(opts.step_chunk))
    if opts.gui:
        bridge['gui'] = 'true'
    if opts.seed is not None:
        bridge['item_seed'] = str(opts.seed)
    if port is not None:
        own['cell_viewer'] = {'port': str(port)}
    people = graph.person_params(person, opts.person_seed, opts.monitor_link)
    for name, values in people.items():
        own.setdefault(name, {}).update(values)
    for name, values in graph.line_params(opts.cell, opts.cells).items():
        own.setdefault(name, {}).update(values)
    upstream = tuple(graph.line_upstream(opts.cell, opts.cells))
    faults: Tuple[str, ...] = ()
    if opts.faults:  # every node applies the entries naming its endpoints
        from scara_collab.run.faults import node_entries, slips
        faults = tuple(node_entries(opts.faults))
        slip_at, slip_rate = slips(opts.faults)  # the world's: the bridge drops the item
        if slip_at:
            bridge['slip_at'] = ','.join(repr(float(t)) for t in slip_at)
        if slip_rate > 0:
            bridge['slip_rate'] = repr(float(slip_rate))
        at = crashes(opts).get('pybullet_bridge')
        if at is not None and 0 < at < float(opts.duration):
            bridge['pause_at'] = repr(float(at))  # where the supervisor kills it
    out = []
    for spec in specs:
        params = dict(common, **by_mode[spec.name], **own.get(spec.name, {}))
        out.append(Stage(spec.name, spec.entry, spec.configs,
                         spec.ready.describe(spec.name, params, opts.namespace), params,
                         namespace=opts.namespace, upstream=upstream, faults=faults))
    return out


def crashes(opts: LaunchOptions) -> Dict[str, float]:
    """Return the crashes ``--fault`` asks of this cell's nodes: ``{node name: sim s}``.

    A crash names a node by its fully qualified name (``/cell_1/pybullet_bridge``); those of
    other cells (a line passes the same entries to every cell) are not this cell's.
    """
    if not opts.faults:
        return {}
    from scara_collab.run.faults import crashes as named
    prefix = graph.namespace_of(opts.namespace) + '/'
    return {name[len(prefix):]: at for name, at in named(opts.faults).items()
            if name.startswith(prefix) and name[len(prefix):] in graph.BY_NAME}


def node_args(stage: Stage, config_dir: Path) -> List[str]:
    """Return the ``--ros-args`` of one stage's node."""
    return graph.ros_args(stage.configs, stage.params, config_dir=config_dir,
                          namespace=stage.namespace, upstream=stage.upstream)


def command(stage: Stage, config_dir: Path) -> List[str]:
    """Return the command line of one stage (or of the one process running ``members``)."""
    if stage.members:
        cmd = [sys.executable, '-m', stage.entry] + fault_args(stage.members[0].faults)
        for member in stage.members:
            cmd += ['--node', member.entry] + node_args(member, config_dir)
        return cmd
    return [sys.executable, '-m', 'scara_collab.run.child', stage.entry] + fault_args(
        stage.faults) + node_args(stage, config_dir)


def fault_args(faults: Sequence[str]) -> List[str]:
    """Return ``--fault SPEC`` per entry (:func:`scara_collab.run.child.take_faults`)."""
    return [a for spec in faults for a in ('--fault', spec)]


def one_process(members: Sequence[Stage]) -> Stage:
    """Return the stage running ``members`` in one process (:mod:`scara_collab.run.container`)."""
    return Stage(CONTAINER, 'scara_collab.run.container', (),
                 f'{len(members)} nodes on one executor', {}, tuple(members))
