"""Loading and writing dataclass configs as YAML, with errors that name the key.

Every configurable part of mrslam is a (frozen) dataclass whose field defaults are the only
defaults in the project. This module turns nested dicts (from YAML or ROS parameters) into those
dataclasses and back, strictly: unknown keys, missing required keys and wrong types raise
:class:`ConfigError` naming the dotted key.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import sys
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from mrslam_core.errors import InputError

T = TypeVar("T")


class ConfigError(InputError, ValueError):
    """A config file or mapping does not fit the config dataclasses."""


def _check_scalar(value: Any, typ: Any, key: str) -> Any:
    if typ is Any:
        return value
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if typ is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    raise ConfigError(f"{key}: unsupported field type {typ!r}")


def _convert(value: Any, typ: Any, key: str) -> Any:
    origin = typing.get_origin(typ)
    if dataclasses.is_dataclass(typ):
        if not isinstance(value, dict):
            raise ConfigError(f"{key}: expected a mapping, got {value!r}")
        return from_dict(typ, value, prefix=key + ".")
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(typ)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(value, arg, key)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError("; ".join(errors))
    if origin is typing.Literal:
        allowed = typing.get_args(typ)
        if value not in allowed:
            raise ConfigError(f"{key}: expected one of {list(allowed)}, got {value!r}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        args = typing.get_args(typ)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ConfigError(f"{key}: expected {len(args)} values, got {len(value)}")
            return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        inner = args[0] if args else Any
        items = [_convert(v, inner, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{key}: expected a mapping, got {value!r}")
        _, vtyp = typing.get_args(typ)
        return {str(k): _convert(v, vtyp, f"{key}.{k}") for k, v in value.items()}
    return _check_scalar(value, typ, key)


def from_dict(cls: type[T], data: dict[str, Any] | None, prefix: str = "") -> T:
    """Build dataclass ``cls`` from a nested mapping; absent keys take the field defaults.

    A nested section that gives only some keys keeps the rest of the field's own default (the
    parent's ``default_factory``, which may differ from the nested class's defaults): a team
    config's ``filter: {seed: 1}`` changes the seed of the team's filter, nothing else.

    Raises:
        ConfigError: on an unknown key, a missing required key, or a value of the wrong type.
    """
    data = dict(data or {})
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    odd = [k for k in data if not isinstance(k, str)]
    if odd:  # e.g. YAML reads `1:`, `null:` or `yes:` as a number, None or a bool
        raise ConfigError(
            f"key {prefix}{odd[0]!r} is a {type(odd[0]).__name__}, not a name "
            f"(known keys of {prefix or 'the config'}: {', '.join(sorted(fields))})"
        )
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"unknown key {prefix}{unknown[0]} (known keys of {prefix or 'the config'}: "
            f"{', '.join(sorted(fields))})"
        )
    kwargs = {}
    for name, field in fields.items():
        key = prefix + name
        if name in data:
            value = data[name]
            if isinstance(value, dict):
                default = field.default_factory() if field.default_factory is not dataclasses.MISSING else field.default
                if dataclasses.is_dataclass(default) and not isinstance(default, type):
                    value = _overlay(to_dict(default), value)
            kwargs[name] = _convert(value, hints[name], key)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise ConfigError(f"missing required key {key}")
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        text = str(exc)
        if text.split(" ", 1)[0] in fields:  # a message about one of the keys: name it in full
            raise ConfigError(f"{prefix}{text}") from exc
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: {text}") from exc


def _overlay(base: dict, over: dict) -> dict:
    """``base`` with the keys of ``over`` put in, nested mappings key by key."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _overlay(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def to_dict(obj: Any) -> Any:
    """Dataclass (nested) to plain dicts/lists, ready for YAML or JSON."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    return obj


def _read_mapping(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping")
    return data


def load_yaml(cls: type[T], path: str | Path) -> T:
    """Read a YAML file into dataclass ``cls`` (see :func:`from_dict`)."""
    path = Path(path)
    try:
        return from_dict(cls, _read_mapping(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def _profiles_dir() -> Path:
    """config/ of the checkout (a source tree or an editable install), else share/mrslam/config of
    the environment the package is installed in (pyproject.toml's data-files put it there)."""
    checkout = Path(__file__).resolve().parents[1] / "config"
    return checkout if checkout.is_dir() else Path(sys.prefix) / "share" / "mrslam" / "config"


#: the folder of the named profiles: sim_team.yaml (the simulated team), real_stereo.yaml (a robot
#: with a real stereo head), mrclam.yaml (the MR.CLAM filter), and the launch files
PROFILES = _profiles_dir()


def _profile_parameters(path: Path) -> dict:
    """A profile's mapping: a ROS params file's ``/**: ros__parameters`` or the file's top level."""
    data = _read_mapping(path)
    if set(data) == {"/**"}:
        data = (data["/**"] or {}).get("ros__parameters", {}) or {}
    return data


@functools.lru_cache(maxsize=None)
def _cached_profile(path: Path) -> dict:
    return _profile_parameters(path)


def profile_section(cls: type[T], name: str, section: str) -> T:
    """Section ``section`` of the named profile ``PROFILES / name`` as dataclass ``cls``: the class
    default of a config whose values live in that profile (the file is read once)."""
    path = PROFILES / name
    try:
        return from_dict(cls, copy.deepcopy(_cached_profile(path).get(section) or {}))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {section}: {exc}") from exc


def load_profile(cls: type[T], path: str | Path, overrides: dict[str, Any] | None = None) -> T:
    """Read a named profile into dataclass ``cls``: the sections of the profile that are fields of
    ``cls``, then ``overrides`` (a nested mapping) on top.

    A profile (config/*.yaml) is a ROS params file (``/**: ros__parameters: {...}``), so the
    launcher hands the same file to every node: each node, and each offline pipeline, takes the
    sections (``frontend``, ``filter``, ``exploration``, ...) its config has. Within a section,
    keys are checked strictly (:func:`from_dict`).
    """
    path = Path(path)
    data = _profile_parameters(path)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    picked = {k: v for k, v in data.items() if k in names}
    try:
        return from_dict(cls, _overlay(picked, overrides or {}))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def write_yaml(obj: Any, path: str | Path) -> None:
    """Write a config dataclass as YAML (the effective config written next to every result)."""
    Path(path).write_text(yaml.safe_dump(to_dict(obj), sort_keys=False))


def flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """Dataclass to ``{"a.b.c": value}``: the ROS parameter names of a config."""
    return flatten_dict(to_dict(obj), prefix)


def flatten_dict(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            out.update(flatten_dict(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1}`` to ``{"a": {"b": 1}}`` (ROS parameters back to a nested config)."""
    out: dict[str, Any] = {}
    for name, value in flat.items():
        node = out
        parts = name.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


def _bounded(text: str, kind: type, low: float, strict: bool, what: str):
    """An argparse value of type ``kind`` (int or float), finite, above ``low`` (or at least, unless ``strict``)."""
    import argparse

    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
    if not (value > low if strict else value >= low) or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be {what}, got {text}")
    return value


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1 (a team size, a count)."""
    return _bounded(text, int, 1, False, "at least 1")


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0 (a seed)."""
    return _bounded(text, int, 0, False, ">= 0")


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0 (a duration)."""
    return _bounded(text, float, 0.0, True, "> 0")
