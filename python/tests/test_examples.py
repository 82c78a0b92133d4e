"""The example planners finish episodes, as scripts and as planners."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import objview
from conftest import TOKEN

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))

from farthest_view import FarthestViewPlanner, directions  # noqa: E402
from random_planner import RandomPlanner  # noqa: E402


def run_script(server, name, tmp_path, *args):
    out = tmp_path / f"{name}.jsonl"
    p = subprocess.run(
        [sys.executable, str(EXAMPLES / name), "--url", server.url, "--token", TOKEN,
         "--split", "tiny", "--out", str(out), *args],
        capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert p.returncode == 0, p.stderr
    return p.stdout, [json.loads(line) for line in out.read_text().splitlines()]


def test_farthest_view_script(server, client, tmp_path):
    stdout, res = run_script(server, "farthest_view.py", tmp_path, "--budget", "5",
                             "--method", "t-farthest")
    assert [r["uid"] for r in res] == ["cube", "cone"]
    assert "cube:" in stdout and "cone:" in stdout
    cands = client.candidate_set("tammes-360")
    for r in res:
        assert r["terminal_reason"] == "plan_end" and r["method"] == "t-farthest"
        poses = np.asarray(r["visited_poses"])
        assert len(poses) == 6 and r["checkpoints"]["K=5"]["views"] == 6
        # The greedy rule, recomputed: each move maximizes the minimum angle to the views so
        # far (ties to the lowest index).
        cd = directions(cands)
        for k in range(1, len(poses)):
            seen = directions(poses[:k])
            score = np.max(np.clip(cd @ seen.T, -1, 1), axis=1)
            visited = [int(np.flatnonzero((cands == p).all(axis=1))[0]) for p in poses[1:k]]
            score[visited] = np.inf
            assert (cands[int(np.argmin(score))] == poses[k]).all(), k
        # The first move goes (nearly) opposite the start direction (1, 1, 1).
        assert directions(poses[1])[0] @ (np.ones(3) / np.sqrt(3)) < -0.98
    assert [r["uid"] for r in client.results("t-farthest")] == ["cube", "cone"]


def test_random_script(server, tmp_path):
    stdout, res = run_script(server, "random_planner.py", tmp_path, "--budget", "5",
                             "--objects", "1", "--space", "quarter", "--method", "t-random")
    (r,) = res
    assert r["uid"] == "cone" and r["terminal_reason"] == "plan_end"
    poses = np.asarray(r["visited_poses"])
    assert len(poses) == 6 and len({tuple(p) for p in poses[1:]}) == 5  # distinct
    assert (poses[:, 1] >= -1e-9).all() and (poses[:, 2] >= -1e-9).all()  # quarter


def test_random_planner_is_seeded_by_the_episode(client):
    a = objview.run_planner(client, RandomPlanner(), "tiny", objects=[0], budget=5,
                            method="t-random-seed", seed=4, eager_depth=False)
    b = objview.run_planner(client, RandomPlanner(), "tiny", objects=[0], budget=5,
                            method="t-random-seed", seed=4, eager_depth=False)
    c = objview.run_planner(client, RandomPlanner(), "tiny", objects=[0], budget=5,
                            method="t-random-seed", seed=5, eager_depth=False)
    assert a[0]["visited_poses"] == b[0]["visited_poses"] != c[0]["visited_poses"]


def test_auto_budget_runs_until_the_server_stops(client):
    (r,) = objview.run_planner(client, FarthestViewPlanner(), "tiny", objects=["cube"],
                               budget="auto", method="t-farthest-auto", eager_depth=False)
    # auto for an iterative planner: the server ends the run itself (enough_info once every
    # checkpoint exists, or the cap); the auto budget is read at MS@0.02.
    assert r["terminal_source"] == "benchmark", r["terminal_reason"]
    assert "MS@0.02" in r["checkpoints"]


def test_auto_summary_line_shows_the_ms_checkpoint(server, tmp_path):
    stdout, res = run_script(server, "farthest_view.py", tmp_path, "--budget", "auto",
                             "--objects", "cube", "--method", "t-farthest-auto-line")
    (r,) = res
    line = next(x for x in stdout.splitlines() if x.startswith("cube:"))
    ms = r["checkpoints"]["MS@0.02"]
    assert f"auto (MS@0.02): {ms['views']} views" in line, line
    assert f"NSC@0.02 {ms['nsc']['0.02']:.3f}" in line.split("auto (MS@0.02)")[1]


def test_examples_take_the_token_from_the_environment(server, tmp_path):
    out = tmp_path / "r.jsonl"
    p = subprocess.run(
        [sys.executable, str(EXAMPLES / "random_planner.py"), "--split", "tiny", "--budget", "1",
         "--objects", "0", "--method", "t-env-token", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "OBJVIEW_URL": server.url, "OBJVIEW_TOKEN": TOKEN},
    )
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text())["method"] == "t-env-token"
