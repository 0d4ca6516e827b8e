"""What every experiment writes: its Markdown table (also printed) and its numbers as JSON."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_tables(out: str | Path, name: str, text: str, data: Any) -> Path:
    """Print ``text``, write ``<out>/<name>.md`` and ``<out>/<name>.json`` (``data``); returns the .md path."""
    print(text)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = out / f"{name}.md"
    md.write_text(text + "\n")
    (out / f"{name}.json").write_text(json.dumps(data, indent=2, default=float))
    print(f"wrote {md}")
    return md
