"""A local `objview run` replayed through the server gives identical checkpoints."""

from __future__ import annotations

import json

import numpy as np

import objview
from conftest import run_bin

CHECKPOINT_FIELDS = ("views", "sc", "nsc", "cd", "path_cost")


class ReplayPlanner(objview.Planner):
    """Plays a fixed list of poses, then stops with plan_end."""

    family = "baseline"

    def __init__(self, poses):
        self.poses = [list(map(float, p)) for p in poses]

    def reset(self, episode):
        self.i = 0

    def act(self, observation, episode):
        if self.i >= len(self.poses):
            return ("stop", "plan_end")
        p = self.poses[self.i]
        self.i += 1
        return ("move", p)


def test_replay_of_a_local_run_matches_checkpoints(server, client, pool, objview_bin, tmp_path):
    out = tmp_path / "local.jsonl"
    run_bin(
        objview_bin, "run", "--planner", "random", "--seed", "7", "--space", "whole",
        "--budget", "5", "--no-timings", "--objects", str(pool.split_file("solo")),
        "--normalize", "none", "--cache-dir", str(tmp_path / "cache"), "--threads", "1",
        "--out", str(out), "--quiet",
    )
    (local,) = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    assert local["uid"] == "cube" and "error" not in local

    planner = ReplayPlanner(local["visited_poses"][1:])
    (remote,) = objview.run_planner(
        client, planner, "solo", view_space="whole", budget=5, method="t-replay",
        family="baseline", execution_mode="iterative", seed=7, record_timings=False,
        eager_depth=False,
    )
    assert remote["uid"] == local["uid"]
    # Every pose was played and the server ended the run where the local one ended.
    assert remote["visited_poses"] == local["visited_poses"]
    assert remote["terminal_reason"] == local["terminal_reason"]
    assert remote["terminal_source"] == local["terminal_source"]
    assert set(remote["checkpoints"]) == set(local["checkpoints"])
    for name, cp in local["checkpoints"].items():
        got = remote["checkpoints"][name]
        for f in CHECKPOINT_FIELDS:
            assert got[f] == cp[f], f"{name}.{f}: server {got[f]} != local {cp[f]}"
        assert got["runtime"] == 0.0  # record_timings false
    # Per-step metrics too (wall-clock fields aside).
    assert len(remote["steps"]) == len(local["steps"])
    for a, b in zip(remote["steps"], local["steps"]):
        for f in CHECKPOINT_FIELDS:
            if f in b:
                assert a[f] == b[f], (f, a, b)
    # The per-episode seed the server hands a planner is the one a local run uses.
    assert remote["seed"] == local["seed"] == 7


def test_replay_planner_sees_the_server_seed(client):
    seeds = []

    class Probe(ReplayPlanner):
        def reset(self, episode):
            super().reset(episode)
            seeds.append(episode.seed)

    objview.run_planner(client, Probe([]), "solo", budget=5, seed=7, method="t-replay-seed")
    objview.run_planner(client, Probe([]), "solo", budget=5, seed=7, method="t-replay-seed")
    objview.run_planner(client, Probe([]), "solo", budget=30, seed=7, method="t-replay-seed")
    assert seeds[0] == seeds[1] and seeds[0] != seeds[2]
    assert all(isinstance(s, int) and s >= 0 for s in seeds)
    assert np.all(np.asarray([r["terminal_reason"] for r in client.results("t-replay-seed")])
                  == "plan_end")
