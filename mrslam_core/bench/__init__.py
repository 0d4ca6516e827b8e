"""Benchmarks: ``mrslam bench NAME [ARGS]`` runs ``mrslam_core.bench.NAME.main(ARGS)``.

Each benchmark prints its figures and writes JSON under ``--out`` (default ``runs/bench``).
"""

from mrslam_core.subcommands import dispatch


def main(argv: list[str]) -> int:
    return dispatch(__name__, __path__, "bench", argv)
