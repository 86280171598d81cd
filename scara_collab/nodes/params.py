"""Declare the ``config/*.yaml`` keys as ROS parameters, read them back, validate them.

A node calls :func:`declare_config` with the config files it uses. Every key of those files
becomes a parameter (nested keys joined with dots, e.g. ``pid.planar.kp``) whose default is
the package's file, so ``--ros-args --params-file config/<file>.yaml`` (or ``-p key:=value``)
overrides it. The values are re-assembled into the nested tree the core expects and
validated with :func:`scara_collab.core.config.validate`; an invalid value stops the node
with the file's error message. Later changes go through the same validation in an
on-set-parameters callback and are refused unless the key is listed as dynamic.

A node's own parameters (not in a file) get the same treatment from :func:`declare_checked`,
with the rules of :class:`scara_collab.core.config.Rule`.
"""
import copy
from typing import Callable, Dict, Iterable, Optional, Sequence

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node

from scara_collab.core.config import check_rules, ConfigError, load_config, Rule, validate


def flatten(tree: dict, prefix: str = '') -> Dict[str, object]:
    """Flatten a tree: ``{"a": {"b": 1}}`` -> ``{"a.b": 1}``."""
    out = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def unflatten(flat: Dict[str, object]) -> dict:
    """Inverse of :func:`flatten`."""
    tree: dict = {}
    for name, value in flat.items():
        node = tree
        *parents, leaf = name.split('.')
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return tree


def _plain(value):
    """ROS array parameters come back as array.array / numpy: make them lists."""
    if isinstance(value, (str, bool, int, float)) or value is None:
        return value
    return list(value)


def declare_config(node: Node, names: Sequence[str], dynamic: Iterable[str] = (),
                   on_change: Optional[Callable[[str, dict], None]] = None) -> Dict[str, dict]:
    """Declare every key of the named config files and return the validated trees.

    :param node: the node that owns the parameters.
    :param names: config files, e.g. ``('simulation', 'controllers')``.
    :param dynamic: keys that may change while the node runs (others are read-only).
    :param on_change: called with ``(file name, new tree)`` after an accepted change.
    :return: ``{file name: nested parameter tree}``.
    :raises ConfigError: if an overridden value is invalid.
    """
    dynamic = set(dynamic)
    owners: Dict[str, str] = {}
    trees: Dict[str, dict] = {}
    for name in names:
        defaults = flatten(load_config(name))
        for key, value in defaults.items():
            owners[key] = name
            desc = ParameterDescriptor(dynamic_typing=True, read_only=key not in dynamic,
                                       description=f'config/{name}.yaml: {key}')
            node.declare_parameter(key, value, desc)
        flat = {k: _plain(node.get_parameter(k).value) for k in defaults}
        trees[name] = validate(name, unflatten(flat), where=f'{node.get_name()} ({name})')

    def check(params):
        changed: Dict[str, dict] = {}
        for p in params:
            file = owners.get(p.name)
            if file is None:
                continue  # not one of ours (use_sim_time, ...)
            tree = changed.setdefault(file, copy.deepcopy(trees[file]))
            node_ = tree
            *parents, leaf = p.name.split('.')
            for part in parents:
                node_ = node_[part]
            node_[leaf] = _plain(p.value)
        try:
            for file, tree in changed.items():
                validate(file, tree, where=f'{node.get_name()} ({file})')
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        for file, tree in changed.items():
            trees[file].clear()
            trees[file].update(tree)
            if on_change is not None:
                on_change(file, trees[file])
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(check)
    return trees


def declare_checked(node, defaults: Dict[str, object], rules: Sequence[Rule],
                    dynamic: Iterable[str] = (),
                    on_change: Optional[Callable[[Dict[str, object]], None]] = None
                    ) -> Dict[str, object]:
    """Declare a node's own parameters and refuse values that break ``rules``.

    What :func:`declare_config` does for the config files' keys,
    for parameters that are not in a file: each is declared with its default (any type, so
    the rule gives the reason for a wrong one) and read only unless it is in ``dynamic``; an
    invalid value stops the node at start, and is refused by an on-set-parameters callback
    at run time. An accepted change updates the returned dict and calls ``on_change`` with
    it.

    :param node: the node that owns the parameters.
    :param defaults: ``{name: default}``.
    :param rules: the checks (:class:`scara_collab.core.config.Rule`), one per name.
    :param dynamic: the names that may change while the node runs.
    :param on_change: called with all the values after an accepted change.
    :return: ``{name: value}``, the values in force.
    :raises ConfigError: ``'<node>: <name> must be ..., got ...'`` for an invalid value.
    """
    dynamic = set(dynamic)
    for name, value in defaults.items():
        node.declare_parameter(name, value, ParameterDescriptor(
            dynamic_typing=True, read_only=name not in dynamic))
    values = check_rules(rules, {name: node.get_parameter(name).value for name in defaults},
                         node.get_name())

    def proposed(params) -> Dict[str, object]:
        return {p.name: p.value for p in params if p.name in values}

    def check(params) -> SetParametersResult:
        try:
            check_rules(rules, {**values, **proposed(params)}, node.get_name())
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def apply(params) -> None:
        changed = proposed(params)
        if changed:
            values.update(changed)
            if on_change is not None:
                on_change(values)

    node.add_on_set_parameters_callback(check)
    node.add_post_set_parameters_callback(apply)
    return values
