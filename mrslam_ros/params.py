"""ROS parameters declared from the core's config dataclasses, and read back into them.

A node declares one parameter per leaf field of its config, named by the dotted path
(``filter.motion.alpha1``), typed and defaulted from the dataclass itself, so the YAML in config/
(``--ros-args --params-file``), the ROS parameters and the core's fields share one set of names and
one set of defaults. Nested YAML in a params file is the same as dotted names::

    /**:
      ros__parameters:
        filter: {num_particles: 200, motion: {alpha1: 0.05}}

Types: ``int``, ``bool``, ``str`` and ``Literal`` fields are declared with their type, so ROS
rejects a wrong type at once. ``float`` fields (and float arrays, and optional ``X | None`` fields)
are declared dynamically typed, because YAML writes ``1`` for a float one and ROS would refuse it;
:func:`read_config` checks every value through :func:`mrslam_core.configio.from_dict`, which
accepts an integer for a float and names the key of anything else. Tuples and lists become arrays;
an empty default is declared with its element type and read back as empty.

Keys of the params file that no field declares (typos) are reported by :func:`unknown_overrides`;
:func:`read_config` logs them, or raises with ``strict=True``. A params file can serve several
nodes (a profile such as config/real_stereo.yaml, with a section per node): a key under a section
the node does not have, and close to none of its names, is another node's and is not reported.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from mrslam_core.configio import ConfigError, flatten, from_dict, unflatten

T = TypeVar("T")

#: Parameters every rclpy node has, or that rclpy handles itself; never reported as unknown.
ROS_OWN = ("use_sim_time", "start_type_description_service", "qos_overrides.")

_ARRAY_TYPES = {int: Parameter.Type.INTEGER_ARRAY, float: Parameter.Type.DOUBLE_ARRAY,
                str: Parameter.Type.STRING_ARRAY, bool: Parameter.Type.BOOL_ARRAY}


def leaf_types(cls: type, prefix: str = "") -> dict[str, Any]:
    """``{"a.b.c": type annotation}`` of every leaf field of dataclass ``cls`` (nested dataclasses
    expanded), in the order :func:`mrslam_core.configio.flatten` lists them."""
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        typ = hints[f.name]
        if dataclasses.is_dataclass(typ):
            out.update(leaf_types(typ, f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = typ
    return out


def _element(typ: Any) -> Any:
    args = [a for a in typing.get_args(typ) if a is not Ellipsis]
    return args[0] if args else Any


def _descriptor(name: str, typ: Any) -> tuple[ParameterDescriptor, Parameter.Type | None]:
    """(descriptor, array type for an empty default) of a field annotated ``typ``."""
    origin = typing.get_origin(typ)
    dynamic = typ is float or origin in (typing.Union, types.UnionType)
    array_type = None
    if origin in (tuple, list):
        elem = _element(typ)
        dynamic = elem is float
        array_type = _ARRAY_TYPES.get(elem, Parameter.Type.DOUBLE_ARRAY)
    return ParameterDescriptor(name=name, description=str(typ).replace("typing.", ""), dynamic_typing=dynamic), array_type


def declare_config(node: Node, default: Any, prefix: str = "") -> None:
    """Declare every leaf of dataclass instance ``default`` as a parameter of ``node``.

    Values given on the command line or in a ``--params-file`` override the defaults as usual.

    Raises:
        rclpy.exceptions.InvalidParameterTypeException: an override of the wrong type for an
            int, bool or str field (the message names the parameter).
    """
    types_ = leaf_types(type(default), prefix)
    for name, value in flatten(default, prefix).items():
        descriptor, array_type = _descriptor(name, types_.get(name, Any))
        if value is None:
            descriptor.dynamic_typing = True
            node.declare_parameter(name, None, descriptor)
        elif isinstance(value, list) and not value:
            descriptor.dynamic_typing = False  # rclpy takes a type or dynamic typing, not both
            node.declare_parameter(name, array_type or Parameter.Type.DOUBLE_ARRAY, descriptor)
        else:
            node.declare_parameter(name, value, descriptor)


def unknown_overrides(node: Node) -> list[str]:
    """Parameter overrides given to ``node`` (params file, ``-p``) that it never declared and that
    look meant for it: under a section (the first part of a dotted name) it declares, or close to
    one of its names (``fliter.num_particles``, ``robts``). The others are left to the nodes that
    share the params file (the slam node's ``filter`` in a frontend's profile); rclpy ignores
    overrides a node never declares."""
    overrides = getattr(node, "_parameter_overrides", {})  # rclpy keeps them until declared
    declared = list(node.list_parameters([], 0).names)
    sections = sorted({name.split(".", 1)[0] for name in declared if "." in name})
    top = [name for name in declared if "." not in name]

    def meant(key: str) -> bool:
        if "." in key:  # its section is this node's, or a misspelling of one (fliter -> filter)
            section = key.split(".", 1)[0]
            return section in sections or bool(difflib.get_close_matches(section, sections, n=1, cutoff=0.8))
        return bool(difflib.get_close_matches(key, top, n=1))  # robts -> robots

    return sorted(k for k in overrides if not node.has_parameter(k) and not k.startswith(ROS_OWN) and meant(k))


def read_config(node: Node, cls: type[T], prefix: str = "", strict: bool = False) -> T:
    """The config dataclass ``cls`` from ``node``'s parameters declared by :func:`declare_config`.

    Args:
        node: the node.
        cls: the config dataclass (its defaults fill parameters that have no value).
        prefix: the name prefix used when declaring.
        strict: raise on params-file keys no field declares (else they are logged as warnings).

    Raises:
        mrslam_core.configio.ConfigError: a parameter value the dataclass rejects (named), or with
            ``strict``, unknown keys (named, with the closest known key).
    """
    defaults = flatten(cls(), prefix)
    unknown = unknown_overrides(node)
    if unknown:
        hints = []
        for key in unknown:
            close = difflib.get_close_matches(key, list(defaults), n=1)
            hints.append(f"{key} (did you mean {close[0]}?)" if close else key)
        text = f"unknown parameter(s) for {node.get_fully_qualified_name()}: {', '.join(hints)}"
        if strict:
            raise ConfigError(text)
        node.get_logger().warning(text)
    values = {}
    for name, default in defaults.items():
        try:
            value = node.get_parameter(name).value
        except ParameterUninitializedException:
            value = default
        if value is not None and not isinstance(value, (bool, int, float, str)):
            value = list(value)  # arrays arrive as array.array or lists
        values[name[len(prefix):]] = value
    return from_dict(cls, unflatten(values))
