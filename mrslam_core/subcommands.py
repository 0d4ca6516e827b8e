"""Sub-command packages: ``mrslam VERB NAME [ARGS]`` runs ``<package>.NAME.main(ARGS)``."""

from __future__ import annotations

import importlib
import pkgutil
import sys
from collections.abc import Iterable


def dispatch(package: str, path: Iterable[str], verb: str, argv: list[str]) -> int:
    """Run module ``package.NAME``'s ``main(argv[1:])`` where NAME = ``argv[0]``."""
    names = sorted(m.name for m in pkgutil.iter_modules(path) if not m.name.startswith("_"))
    if not argv or argv[0] in ("-h", "--help"):
        print(f"usage: mrslam {verb} {{{','.join(names)}}} [ARGS]")
        return 0
    if argv[0] not in names:
        print(f"mrslam {verb}: unknown name {argv[0]!r}; have {names}", file=sys.stderr)
        return 2
    return int(importlib.import_module(f"{package}.{argv[0]}").main(argv[1:]) or 0)
