#!/usr/bin/env python3
"""Random next-best-view planner against an objview server.

Each step moves to a candidate drawn uniformly from the feasible candidates not visited yet
(tammes-360 by default), with numpy's generator seeded by the episode's seed (the per-episode
seed the server returns, the one a local `objview run --seed S` hands its planners — the draws
themselves differ from the Rust `random` planner's ChaCha8).  With a fixed budget K it stops with
`plan_end` after K moves; with `auto` it runs until the server ends the episode (MS@0.02,
`enough_info` or the cap), or stops with `candidate_exhausted` when no candidate is left.

    python examples/random_planner.py --url http://127.0.0.1:8080 --token TOKEN --split main_hidden_test --budget 5
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


class RandomPlanner(objview.Planner):
    name = "py-random"
    family = "baseline"
    execution_mode = "iterative"
    params = {"rule": "uniform over feasible unvisited candidates", "rng": "numpy PCG64(seed)"}

    def reset(self, episode: objview.Episode) -> None:
        self.rng = np.random.default_rng(int(episode.seed or 0))
        self.candidates = np.asarray(episode.candidates)
        self.feasible = episode.feasible(self.candidates)
        self.visited = np.zeros(len(self.candidates), dtype=bool)
        self.moves = 0
        self.budget = episode.fixed_budget

    def act(self, observation: objview.Observation, episode: objview.Episode):
        if self.budget is not None and self.moves >= self.budget:
            return ("stop", "plan_end")
        choices = np.flatnonzero(self.feasible & ~self.visited)
        if choices.size == 0:
            return ("stop", "candidate_exhausted")
        i = int(choices[self.rng.integers(choices.size)])
        self.visited[i] = True
        self.moves += 1
        return ("move", self.candidates[i])


if __name__ == "__main__":
    from _common import main, parse_args

    args = parse_args(__doc__.splitlines()[0], RandomPlanner.name)
    main(RandomPlanner(), args)
