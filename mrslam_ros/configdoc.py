"""The configuration reference (docs/configuration.md), generated from the config dataclasses.

Every key a YAML file or a ROS parameter can set, with its type, its default and its meaning (from
the class's ``Attributes:`` docstring). ``python -m mrslam_ros.configdoc --write`` rewrites the
page; ``test/ros/test_configdoc.py`` fails when the page and the dataclasses differ.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import typing
from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "configuration.md"

#: (config, what reads it), the configs a user writes, in the page's order
TOP = (
    ("mrslam_ros.demo:DemoConfig", "`mrslam demo --config Y` (its `team` is the TeamConfig)"),
    ("mrslam_core.pipelines.team:TeamConfig", "`mrslam team --config Y`; `mrslam demo`'s `team`"),
    ("mrslam_ros.launch:LaunchConfig", "`mrslam launch Y`"),
    ("mrslam_ros.sim_node:SimNodeConfig", "the simulator node's ROS parameters"),
    ("mrslam_ros.frontend_node:FrontendNodeConfig", "a stereo frontend node's ROS parameters"),
    ("mrslam_ros.slam_node:SlamNodeConfig", "the central SLAM node's ROS parameters (`mrslam replay --offline` too)"),
    ("mrslam_ros.explore_node:ExploreNodeConfig", "the exploration node's ROS parameters"),
    ("mrslam_ros.view_node:ViewNodeConfig", "the view node's ROS parameters (the Foxglove WebSocket server)"),
    ("mrslam_core.pipelines.mrclam:MrclamConfig", "`mrslam mrclam DIR --config Y`"),
    ("mrslam_core.pipelines.dataset:DatasetRunConfig", "`mrslam dataset run ... --config Y`"),
)


def _load(spec: str) -> type:
    import importlib

    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


def attribute_docs(cls: type) -> dict[str, str]:
    """name -> its description in the ``Attributes:`` sections of ``cls`` and its bases
    (``a, b: text`` documents both; continuation lines are joined)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        doc = klass.__dict__.get("__doc__") or ""
        lines = doc.expandtabs().splitlines()
        for i, line in enumerate(lines):
            if line.strip() != "Attributes:":
                continue
            base = len(line) - len(line.lstrip())
            current: list[str] | None = None
            names: list[str] = []
            for text in lines[i + 1:]:
                if not text.strip():
                    continue
                indent = len(text) - len(text.lstrip())
                if indent <= base:
                    break
                m = re.match(r"^([A-Za-z_][\w]*(?:\s*,\s*[A-Za-z_][\w]*)*)\s*:\s*(.*)$", text.strip())
                if m and (current is None or indent <= entry_indent):
                    if current is not None:
                        for n in names:
                            out[n] = " ".join(current).strip()
                    names = [n.strip() for n in m.group(1).split(",")]
                    current, entry_indent = [m.group(2)], indent
                elif current is not None:
                    current.append(text.strip())
            if current is not None:
                for n in names:
                    out[n] = " ".join(current).strip()
    return out


def prose_docs(cls: type) -> dict[str, str]:
    """name -> description from the other two forms the classes use: a docstring line that starts
    with ````name```` (up to the next such line or a blank line), and a comment after the field
    (``alpha1: float = 0.01  # rad²/rad²``)."""
    import inspect

    out: dict[str, str] = {}
    names = {f.name for f in dataclasses.fields(cls)}
    lines = (cls.__doc__ or "").splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"^``(\w+)``\s*(.*)$", line.strip())
        if not m or m.group(1) not in names:
            continue
        text = [m.group(2).lstrip(":").strip()]
        for more in lines[i + 1:]:
            if not more.strip() or more.strip().startswith("``"):
                break
            text.append(more.strip())
        out.setdefault(m.group(1), " ".join(t for t in text if t))
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return out
    for line in source.splitlines():
        m = re.match(r"^\s+(\w+)\s*:[^=#]+=[^#]*#\s*(.+)$", line)
        if m and m.group(1) in names:
            out.setdefault(m.group(1), m.group(2).strip())
    return out


def _type_name(tp) -> str:
    if typing.get_origin(tp) is not None:
        text = re.sub(r"\b(?:[a-z_][\w]*\.)+([A-Za-z_]\w*)", r"\1", str(tp))
    else:
        text = tp if isinstance(tp, str) else getattr(tp, "__name__", None) or repr(tp)
    return str(text).replace("typing.", "").replace("NoneType", "None")


def _default(value) -> str:
    if dataclasses.is_dataclass(value):
        return f"[{type(value).__name__}](#{type(value).__name__.lower()})"
    return f"`{value!r}`"


def _sections(cls: type, seen: dict[str, type]) -> None:
    instance = cls()
    for f in dataclasses.fields(cls):
        value = getattr(instance, f.name)
        if dataclasses.is_dataclass(value) and type(value).__name__ not in seen:
            seen[type(value).__name__] = type(value)
            _sections(type(value), seen)


def _table(cls: type) -> list[str]:
    docs = prose_docs(cls) | attribute_docs(cls)
    hints = typing.get_type_hints(cls)
    instance = cls()
    rows = ["| key | type | default | meaning |", "|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        value = getattr(instance, f.name)
        meaning = docs.get(f.name) or (f"the `{f.name}` section" if dataclasses.is_dataclass(value) else "")
        meaning = meaning.replace("|", "\\|")
        rows.append(f"| `{f.name}` | {_type_name(hints.get(f.name, f.type)).replace('|', '&#124;')} | "
                    f"{_default(value).replace('|', '&#124;')} | {meaning} |")
    return rows


def render() -> str:
    """The page's Markdown."""
    lines = [
        "# Configuration reference",
        "",
        "Generated from the config dataclasses by `python -m mrslam_ros.configdoc --write` (a test",
        "fails when this page and the code differ). YAML keys are the field names; a nested section",
        "is a mapping (`filter: {num_particles: 300}`); the ROS parameter names are the dotted keys",
        "(`filter.num_particles`). The defaults are the classes'; the profiles in `config/`",
        "(`sim_team.yaml`, `real_stereo.yaml`, `mrclam.yaml`) change some of them, and the",
        "effective config of every run is written next to its results. Units are in the meanings.",
        "",
    ]
    sections: dict[str, type] = {}
    for spec, who in TOP:
        cls = _load(spec)
        lines += [f"## {cls.__name__}", "", f"Read by {who}.", ""] + _table(cls) + [""]
        _sections(cls, sections)
    tops = {_load(spec).__name__ for spec, _ in TOP}
    lines += ["## Sections", ""]
    for name in sorted(sections):
        if name in tops:
            continue
        lines += [f"### {name}", ""] + _table(sections[name]) + [""]
    return "\n".join(lines).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrslam_ros.configdoc", description=__doc__)
    ap.add_argument("--write", action="store_true", help=f"rewrite {PAGE}")
    args = ap.parse_args(argv)
    text = render()
    if args.write:
        PAGE.write_text(text)
        print(f"wrote {PAGE}")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
