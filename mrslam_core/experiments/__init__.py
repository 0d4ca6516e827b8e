"""Experiments: ``mrslam experiment NAME [ARGS]`` runs ``mrslam_core.experiments.NAME.main(ARGS)``.

Each prints its table and writes JSON and Markdown under ``--out`` (default ``runs/experiments``);
the tables are the ones in docs/results.md.
"""

from mrslam_core.subcommands import dispatch


def main(argv: list[str]) -> int:
    return dispatch(__name__, __path__, "experiment", argv)
