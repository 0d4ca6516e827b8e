"""Property-based fuzzing of config loading (hypothesis): config files with missing, extra or
wrong-typed keys at any depth give a ConfigError that names the dotted key; a config without
optional keys is the default; arbitrary YAML text never raises anything but ConfigError.

Configs: the team pipeline's (sim, frontend, filter, exploration, control, grid sections), MR.CLAM's
(config/mrclam.yaml) and the launcher's (config/launch_sim2.yaml: a list of node specs with
required keys).
"""

import copy
import dataclasses
import functools
import types
import typing
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrslam_core.configio import ConfigError, from_dict, load_yaml, to_dict
from mrslam_core.pipelines.mrclam import MrclamConfig
from mrslam_core.pipelines.team import TeamConfig

REPO = Path(__file__).resolve().parents[2]
SETTINGS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _launch_case():
    launch = pytest.importorskip("mrslam_ros.launch")
    return launch.LaunchConfig, yaml.safe_load((REPO / "config" / "launch_sim2.yaml").read_text())


CASES = {
    "team": lambda: (TeamConfig, to_dict(TeamConfig())),
    "mrclam": lambda: (MrclamConfig, yaml.safe_load((REPO / "config" / "mrclam.yaml").read_text())),
    "launch": _launch_case,
}


def walk(cls, data: dict, prefix: str = "", path: tuple = ()):
    """Yield ("leaf" | "map", dotted key, path into ``data``, type hint, field) for every field
    present in ``data`` and every dataclass mapping (nested sections, list items)."""
    yield "map", prefix.rstrip("."), path, cls, None
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        typ, key, value = hints[f.name], prefix + f.name, data[f.name]
        args = typing.get_args(typ)
        if dataclasses.is_dataclass(typ) and isinstance(value, dict):
            yield from walk(typ, value, key + ".", path + (f.name,))
        elif typing.get_origin(typ) in (list, tuple) and args and dataclasses.is_dataclass(args[0]):
            yield "leaf", key, path + (f.name,), typ, f
            for i, item in enumerate(value):
                yield from walk(args[0], item, f"{key}[{i}].", path + (f.name, i))
        else:
            yield "leaf", key, path + (f.name,), typ, f


def fits(value: Any, typ: Any) -> bool | None:
    """Whether ``value`` has the type ``typ`` asks for (as configio reads it); None: unknown."""
    origin, args = typing.get_origin(typ), typing.get_args(typ)
    if typ is Any:
        return True
    if typ is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if typ is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if typ in (bool, str):
        return isinstance(value, typ)
    if origin is typing.Literal:
        return value in args
    if origin in (typing.Union, types.UnionType):
        results = [value is None if a is type(None) else fits(value, a) for a in args]
        return None if None in results and not any(results) else any(r for r in results if r)
    if origin in (list, tuple):
        if not isinstance(value, list):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(fits(v, a) for v, a in zip(value, args))
        results = [fits(v, args[0] if args else Any) for v in value]
        return None if None in results else all(results)
    if origin is dict:
        return isinstance(value, dict) and all(fits(v, args[1]) for v in value.values())
    if dataclasses.is_dataclass(typ):
        return None
    return None


def put(data: dict, path: tuple, value=None, delete: bool = False) -> None:
    node = data
    for p in path[:-1]:
        node = node[p]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value


@functools.cache
def _base(case: str):
    cls, data = CASES[case]()
    return cls, yaml.safe_load(yaml.safe_dump(data))  # YAML types only


def fresh(case: str):
    cls, data = _base(case)
    return cls, copy.deepcopy(data)


WRONG = st.sampled_from(["text", "", [1, "a"], [], {"k": 1}, {}, True, False, 2.5, 7, -3, 0, None, 1e400])


@pytest.mark.parametrize("case", list(CASES))
def test_shipped_config_loads_and_round_trips(case, tmp_path):
    cls, data = fresh(case)
    cfg = from_dict(cls, data)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(to_dict(cfg)))
    assert load_yaml(cls, tmp_path / "c.yaml") == cfg


@pytest.mark.parametrize("case", list(CASES))
@SETTINGS
@given(pick=st.integers(0, 10_000), value=WRONG)
def test_wrong_typed_value_names_the_key(case, pick, value):
    cls, data = fresh(case)
    leaves = [x for x in walk(cls, data) if x[0] == "leaf"]
    _, key, path, typ, _ = leaves[pick % len(leaves)]
    put(data, path, value)
    ok = fits(value, typ)
    try:
        from_dict(cls, data)
    except ConfigError as exc:
        if ok is False:
            assert key in str(exc), (key, str(exc))
        return
    assert ok is not False, f"{key} = {value!r} accepted for {typ}"


@pytest.mark.parametrize("case", list(CASES))
@SETTINGS
@given(pick=st.integers(0, 10_000), name=st.sampled_from(["zz_unknown", "Robots", "filter_", "seed2"]))
def test_unknown_key_names_the_key(case, pick, name):
    cls, data = fresh(case)
    maps = [x for x in walk(cls, data) if x[0] == "map"]
    _, key, path, sub, _ = maps[pick % len(maps)]
    if name in {f.name for f in dataclasses.fields(sub)}:
        return
    node = data
    for p in path:
        node = node[p]
    node[name] = 1
    with pytest.raises(ConfigError) as info:
        from_dict(cls, data)
    assert (f"{key}.{name}" if key else name) in str(info.value)


@pytest.mark.parametrize("case", list(CASES))
@SETTINGS
@given(pick=st.integers(0, 10_000))
def test_missing_key_takes_its_default_or_names_the_key(case, pick):
    cls, data = fresh(case)
    leaves = [x for x in walk(cls, data) if x[0] == "leaf" or x[2]]
    kind, key, path, _, f = leaves[pick % len(leaves)]
    if kind == "map":  # a whole section or list item
        f = None
    put(data, path, delete=True)
    required = f is not None and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    try:
        cfg = from_dict(cls, data)
    except ConfigError as exc:
        assert required or "must" in str(exc) or "unique" in str(exc), str(exc)  # or a cross-field check
        if required:
            assert f"missing required key {key}" in str(exc)
        return
    assert not required
    if f is not None and isinstance(path[-1], str) and len(path) == 1:
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        assert getattr(cfg, f.name) == default


keys = st.one_of(st.text(max_size=6), st.integers(-3, 3), st.booleans(), st.none(), st.floats(allow_nan=False))
yaml_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(keys, inner, max_size=3)),
    max_leaves=8,
)


@pytest.mark.parametrize("case", ["team", "launch"])
@settings(SETTINGS, max_examples=60)
@given(doc=st.one_of(st.dictionaries(keys, yaml_values, max_size=4), yaml_values), text=st.text(max_size=60))
def test_any_yaml_gives_a_config_or_config_error(case, doc, text, tmp_path_factory):
    cls, _ = _base(case)
    folder = tmp_path_factory.mktemp("yaml")
    for body in (yaml.safe_dump(doc, sort_keys=False), text, "filter: {num_particles: 3}\n" + text):
        path = folder / "c.yaml"
        path.write_text(body)
        try:
            load_yaml(cls, path)
        except ConfigError:
            pass


def test_non_string_keys_are_named():
    with pytest.raises(ConfigError, match="key filter.1 is a int"):
        from_dict(TeamConfig, {"filter": {1: 2}})
    with pytest.raises(ConfigError, match="key None is a NoneType"):
        from_dict(TeamConfig, {None: 2})


@pytest.mark.parametrize("case", list(CASES))
@SETTINGS
@given(pick=st.integers(0, 10_000))
def test_a_key_left_out_of_a_section_keeps_the_parents_default(case, pick):
    """Leaving a key out of a nested section gives the value the whole config has by default,
    even where the parent's default for the section differs from the section class's own."""
    cls, data = fresh(case)
    leaves = [x for x in walk(cls, data) if x[0] == "leaf" and len(x[2]) > 1 and all(isinstance(k, str) for k in x[2])]
    if not leaves:
        return
    _, _, path, _, _ = leaves[pick % len(leaves)]
    put(data, path, delete=True)
    got = to_dict(from_dict(cls, data))
    want = to_dict(from_dict(cls, {}))
    for k in path:
        got, want = got[k], want[k]
    assert got == want, path


def test_a_partial_team_filter_section_keeps_the_team_filter():
    cfg = from_dict(TeamConfig, {"filter": {"seed": 7}, "control": {"recovery_time": 1.0, "platform": {"rear": 0.2}}})
    assert cfg.filter.seed == 7 and cfg.control.recovery_time == 1.0 and cfg.control.platform.rear == 0.2
    assert cfg.filter == dataclasses.replace(TeamConfig().filter, seed=7)  # not FilterConfig(seed=7)
    team = TeamConfig().control  # the team profile's platform speeds stay
    platform = dataclasses.replace(team.platform, rear=0.2)
    assert cfg.control == dataclasses.replace(team, recovery_time=1.0, platform=platform)
