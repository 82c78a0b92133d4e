#!/usr/bin/env python3
"""Greedy farthest-view planner against an objview server.

Each step moves to the feasible, not yet visited candidate whose viewing direction (camera
centre minus look-at, normalized) maximizes the minimum angle to the directions of the views
taken so far (the start view included); ties go to the lowest candidate index.  With a fixed
budget K it stops with `plan_end` after K moves; with `auto` it runs until the server ends the
episode, or stops with `candidate_exhausted` when no candidate is left.  It never reads a depth
image: a geometric coverage baseline.

    python examples/farthest_view.py --url http://127.0.0.1:8080 --token TOKEN --split main_hidden_test --budget 5
"""

from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
try:
    import objview
except ImportError:  # not installed: use the package next to the examples
    sys.path.insert(1, os.path.dirname(HERE))
    import objview


def directions(poses: np.ndarray) -> np.ndarray:
    """Unit viewing directions (camera centre − look-at) of poses (M, 7)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 7)
    d = poses[:, :3] - poses[:, 3:6]
    n = np.linalg.norm(d, axis=1, keepdims=True)
    return d / np.where(n > 0, n, 1.0)


class FarthestViewPlanner(objview.Planner):
    name = "py-farthest-view"
    family = "classical"
    execution_mode = "iterative"
    params = {"rule": "max-min angular distance to visited views, ties to the lowest index"}

    def reset(self, episode: objview.Episode) -> None:
        self.candidates = np.asarray(episode.candidates)
        self.dirs = directions(self.candidates)
        self.feasible = episode.feasible(self.candidates)
        self.visited = np.zeros(len(self.candidates), dtype=bool)
        # Cosine of the smallest angle to any visited view = max cosine (monotone in angle).
        self.max_cos = np.full(len(self.candidates), -np.inf)
        self.moves = 0
        self.budget = episode.fixed_budget

    def _visit_direction(self, d: np.ndarray) -> None:
        self.max_cos = np.maximum(self.max_cos, np.clip(self.dirs @ d, -1.0, 1.0))

    def act(self, observation: objview.Observation, episode: objview.Episode):
        # The current view (the start view on the first call) counts as visited.
        self._visit_direction(directions(observation.pose)[0])
        if self.budget is not None and self.moves >= self.budget:
            return ("stop", "plan_end")
        ok = self.feasible & ~self.visited
        if not ok.any():
            return ("stop", "candidate_exhausted")
        # max of the minimum angle = min of the maximum cosine; argmin returns the first
        # (lowest) index among exact ties.
        score = np.where(ok, self.max_cos, np.inf)
        i = int(np.argmin(score))
        self.visited[i] = True
        self.moves += 1
        return ("move", self.candidates[i])


if __name__ == "__main__":
    from _common import main, parse_args

    args = parse_args(__doc__.splitlines()[0], FarthestViewPlanner.name)
    main(FarthestViewPlanner(), args)
