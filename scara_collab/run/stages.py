"""The launcher's processes, planned from :mod:`scara_collab.graph`: one stage per node.

A :class:`Stage` is one node process with its parameters and its command line
(``python -m scara_collab.run.child <module>:<function> --ros-args ...``); with
``--one-process`` one stage runs them all (:func:`one_process`, ``python -m
scara_collab.run.container --node ... --node ...``). With ``--namespace`` every node runs in
the cell's namespace with the cell's remaps (:func:`scara_collab.graph.ros_args`); a cell of a
line of cells (``--line-cell K`` of ``--cells N``) also gets its bridge's line parameters and
its upstream cell's handoff topic (:func:`scara_collab.graph.line_params`).

With ``--fault`` each node process gets the entries the nodes apply (``--fault SPEC`` after
the entry: :mod:`scara_collab.run.child`, :mod:`scara_collab.run.container`); a crash is the
supervisor's (:func:`crashes`), and one that names the bridge also makes it pause at that sim
time (its ``pause_at``), so the supervisor kills it there to the physics step.
"""
import argparse
from dataclasses import dataclass, field
from pathlib import Path
import sys
from typing import Dict, List, Optional, Sequence, Tuple

from scara_collab import graph

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


def stages(args: argparse.Namespace, with_automation: bool) -> List[Stage]:
    """Return the graph for ``args``, in launch order (the nodes of :mod:`scara_collab.graph`)."""
    namespace = graph.namespace_of(getattr(args, 'namespace', None))
    common = {} if args.profile is None else {'profile': args.profile}
    by_mode = graph.job_params(args.mode, getattr(args, 'lockstep', 'on') == 'on')
    port = getattr(args, 'viewer', None)
    specs = graph.job_nodes(automation=with_automation, viewer=port is not None,
                            transforms=bool(getattr(args, 'tf', False)))
    own: Dict[str, Dict[str, str]] = {
        # paused until the job has started (Launcher.start_job), so every run starts at sim
        # time 0 with every node there; the belt feeds from then on
        'pybullet_bridge': {'real_time_factor': repr(float(args.launch_rtf)),
                            'feed_interval': '0.0', 'paused': 'true',
                            # the job window ends at sim t=duration exactly (it starts at 0)
                            'pause_at': repr(float(args.duration)),
                            'lockstep_expect': graph.param_value(graph.lockstep_expect(specs))},
        'automation_manager': {'auto_start': 'false'},  # the launcher starts the job
    }
    bridge = own['pybullet_bridge']
    if args.step_chunk is not None:
        bridge['step_chunk'] = repr(float(args.step_chunk))
    if args.gui:
        bridge['gui'] = 'true'
    if args.seed is not None:
        bridge['item_seed'] = str(args.seed)
    if port is not None:
        own['cell_viewer'] = {'port': str(port)}
    k, cells = getattr(args, 'line_cell', None) or 0, getattr(args, 'cells', 1)
    for name, values in graph.line_params(k, cells).items():
        own.setdefault(name, {}).update(values)
    upstream = tuple(graph.line_upstream(k, cells))
    faults: Tuple[str, ...] = ()
    if getattr(args, 'fault', []):  # every node applies the entries naming its endpoints
        from scara_collab.run.faults import node_entries
        faults = tuple(node_entries(args.fault))
        at = crashes(args, namespace).get('pybullet_bridge')
        if at is not None and 0 < at < float(args.duration):
            bridge['pause_at'] = repr(float(at))  # where the supervisor kills it
    out = []
    for spec in specs:
        params = dict(common, **by_mode[spec.name], **own.get(spec.name, {}))
        out.append(Stage(spec.name, spec.entry, spec.configs,
                         spec.ready.describe(spec.name, params, namespace), params,
                         namespace=namespace, upstream=upstream, faults=faults))
    return out


def crashes(args: argparse.Namespace, namespace: Optional[str] = None) -> Dict[str, float]:
    """Return the crashes ``--fault`` asks of this cell's nodes: ``{node name: sim s}``.

    A crash names a node by its fully qualified name (``/cell_1/pybullet_bridge``); those of
    other cells (a line passes the same entries to every cell) are not this cell's.
    """
    if not getattr(args, 'fault', []):
        return {}
    from scara_collab.run.faults import crashes as named
    ns = graph.namespace_of(getattr(args, 'namespace', None) if namespace is None else namespace)
    prefix = ns + '/'
    return {name[len(prefix):]: at for name, at in named(args.fault).items()
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
