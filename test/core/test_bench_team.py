"""mrslam bench team: the team search finds the threshold, and a small run reports sane figures."""

import json

import pytest

from mrslam_core.bench.team import largest_team, main, run_team


@pytest.mark.parametrize("threshold", [0, 1, 2, 3, 5, 8, 13, 40, 64, 100])
def test_search_finds_the_largest_team_that_keeps_up(threshold):
    calls = []

    def run(k):
        calls.append(k)
        return {"keeps_up": k <= threshold}

    largest, results = largest_team(run, start=2, limit=64)
    assert largest == min(threshold, 64)
    assert len(calls) == len(set(calls)) == len(results) <= 14  # doubling + bisection, no repeats


def test_small_team_run(tmp_path, capsys):
    r = run_team(2, frames=4, landmarks=200, particles=10, warmup=1)
    assert r["robots"] == 2 and r["particles"] == 10 and r["frames"] == 4
    assert 0 < r["step_p50_ms"] <= r["step_p95_ms"] <= r["step_max_ms"]
    assert r["frame_p95_ms"] >= r["step_p95_ms"]  # a frame holds two steps in node mode
    assert 0 < r["observations_per_robot_frame"] <= 20
    assert r["checkpoint_mb"] > 0 and r["map_landmarks"] >= 200
    assert main(["--robots", "2", "--frames", "2", "--landmarks", "100", "--particles", "5",
                 "--mode", "team", "--out", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "team.json").read_text())
    assert out["teams"][0]["mode"] == "team" and "K=  2 team" in capsys.readouterr().out
