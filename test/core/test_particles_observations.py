"""`mrslam experiment particles_observations` (000's Figure 4 in simulation): it writes its table,
numbers and plot, and on a seeded half lap more particles give a smaller error."""

import json

from mrslam_core.experiments.particles_observations import main


def test_more_particles_smaller_error_and_every_output_written(tmp_path):
    assert main(["--particles", "1", "30", "--observations", "10", "--seeds", "2", "--laps", "0.5",
                 "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "particles_observations.json").read_text())
    one, thirty = data["errors"]["1,10"], data["errors"]["30,10"]
    # measured: seed 0 0.804 -> 0.395 m, seed 1 0.701 -> 0.282 m
    assert all(b < 0.7 * a for a, b in zip(one, thirty)), (one, thirty)
    assert all(e < 0.5 for e in thirty)
    assert (tmp_path / "particles_observations.png").stat().st_size > 10_000
    assert "| 30 |" in (tmp_path / "particles_observations.md").read_text()
