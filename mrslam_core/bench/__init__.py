"""Benchmarks: ``mrslam bench NAME [ARGS]`` runs ``mrslam_core.bench.NAME.main(ARGS)``.

Each benchmark prints its figures and writes JSON to ``--out`` (default ``runs/bench``).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def main(argv: list[str]) -> int:
    names = available()
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: mrslam bench {" + ",".join(names) + "} [ARGS]")
        return 0
    if argv[0] not in names:
        print(f"mrslam bench: unknown benchmark {argv[0]!r}; have {names}", file=sys.stderr)
        return 2
    return int(importlib.import_module(f"{__name__}.{argv[0]}").main(argv[1:]) or 0)
