"""ROS parameters declared from the core's config dataclasses, and read back into them.

A node declares one parameter per leaf field of its config, named by the dotted path
(``filter.motion.alpha1``), typed and defaulted from the dataclass itself, so the YAML in config/
(``--ros-args --params-file``), the ROS parameters and the core's fields share one set of names and
one set of defaults. Tuples become arrays; ``None`` defaults (optional numbers) are declared as
dynamically typed parameters.
"""

from __future__ import annotations

from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from mrslam_core.configio import flatten, from_dict, unflatten

T = TypeVar("T")


def declare_config(node: Node, default: Any, prefix: str = "") -> None:
    """Declare every leaf of dataclass instance ``default`` as a parameter of ``node``."""
    for name, value in flatten(default, prefix).items():
        if value is None:
            node.declare_parameter(name, None, ParameterDescriptor(dynamic_typing=True))
        elif isinstance(value, list) and not value:
            node.declare_parameter(name, Parameter.Type.DOUBLE_ARRAY)
        else:
            node.declare_parameter(name, value)


def read_config(node: Node, cls: type[T], prefix: str = "") -> T:
    """The config dataclass ``cls`` from ``node``'s parameters declared by :func:`declare_config`.

    Raises:
        mrslam_core.configio.ConfigError: a parameter value the dataclass rejects (named).
    """
    values = {}
    for name in flatten(cls(), prefix):
        value = node.get_parameter(name).value
        if value is not None and not isinstance(value, (bool, int, float, str)):
            value = list(value)  # arrays arrive as array.array or lists
        values[name[len(prefix):]] = value
    return from_dict(cls, unflatten(values))
