"""A Gymnasium environment over the objview evaluation server.

    import json
    import objview                       # registers "objview/ObjView-v0"
    from objview.gym import ObjViewEnv
    env = ObjViewEnv("http://127.0.0.1:8080", split="main_hidden_test", token="my-token",
                     budget=5, max_moves=5)
    obs, info = env.reset(seed=0)
    terminated = False
    while not terminated:
        action = env.action_space.sample(mask=info["action_mask"])
        obs, reward, terminated, truncated, info = env.step(action)
    print(json.loads(info["result_json"])["checkpoints"]["K=5"])
    env.close()

One Gymnasium episode is one server episode.

- **Actions**: ``Discrete(N + 1)`` — an index ``i < N`` moves the camera to candidate ``i`` of the
  candidate set (``candidate_set``, default tammes-360, N = 360); ``N`` (``stop_action``) stops
  the episode with reason ``plan_end``.  ``step`` also accepts a continuous pose, a numpy array
  of shape (7,) ``[cx, cy, cz, lx, ly, lz, roll]`` (SPEC §2); it is outside ``action_space``
  (which stays Discrete so that standard agents work) but a feasible continuous pose is a legal
  benchmark action.
- **Observations**: ``{"depth": float32 (512, 512) camera-frame z (0 = no hit),
  "pose": float64 (7,), "mask": int8 (N,)}``.  ``mask[i] = 1`` when candidate ``i`` is feasible
  in the episode's view space.  It is queried once per episode (one batch request at reset) and
  does not change during the episode: **visited candidates are not masked out** (SPEC §5 allows
  repeated poses: they are rendered, counted and cost zero path), so an agent that must not
  repeat views keeps its own record.  An infeasible index is sent as it is and ends the episode
  with ``invalid_action`` (the benchmark's rule), so agents should respect the mask.
- **info**: ``step``, ``object_id`` and ``action_mask`` (int8 (N + 1,): the feasible candidates
  and 1 for the stop action, so ``env.action_space.sample(mask=info["action_mask"])`` draws a
  legal action) always; at reset also ``intrinsics`` (the camera dict) and ``candidates``
  (float64 (N, 7)); at the end ``terminal`` (``{"source", "reason", "detail"}``) and
  ``result_json`` (the ``objview run`` result line as a JSON string — flat, so that vector
  environments can aggregate ``info``; ``json.loads`` it, or read :attr:`ObjViewEnv.result`).
- **Reward**: 0.0 at every step.  The benchmark hides every metric of a running episode (the
  object is hidden; coverage, CD and anything derived from the ground truth appear only in the
  result, after the end), so no dense reward can be computed honestly on a hidden split.  Pass
  ``reward_fn(env, obs, info)`` to compute your own (e.g. from ``env.result`` at the end).
- ``terminated`` is True when the episode ended on the server — the stop action, a budget, the
  cap, ``enough_info``, an invalid action, a time limit (a ``step`` that finds the episode
  already ended by the server returns ``terminated=True`` with its ``terminal`` rather than
  raising) — and when ``max_moves`` moves were made; ``truncated`` is always False (the server
  owns every limit).
- **Budgets**: ``budget=K`` does not stop the episode after K moves for an iterative run (the
  server records the K checkpoint and the run goes on until ``enough_info`` or the cap, as a
  local ``objview run``); ``max_moves=K`` makes the environment stop (``plan_end``) after K
  moves, as a fixed-budget planner does.
- **Objects**: without ``objects`` the environment cycles through every object of the split, one
  per ``reset``; ``objects`` restricts (and orders) that cycle (indices or uids);
  ``shard=(i, n)`` keeps every n-th object of the cycle starting at the i-th, so that n
  environments of a vector environment run different objects;
  ``reset(options={"object": o})`` picks one explicitly.
- **Seeding**: ``reset(seed=s)`` restarts the cycle at its first object and makes ``s`` the
  benchmark seed of the following episodes, so the same seed gives the same episode
  (Gymnasium's determinism rule).  With ``shard=(i, n)`` the benchmark seed is ``s - i``:
  Gymnasium's vector environments reset sub-environment ``i`` with ``seed + i``, so every shard
  of ``reset(seed=s)`` runs with benchmark seed ``s``, and a run does not depend on how it was
  sharded.  ``reset()`` without a seed keeps the current one.
- **Abandoned episodes**: an episode still running when ``reset`` or ``close`` is called is
  aborted on the server (source ``exception``, reason ``planner_error``, its views scored) —
  so that nothing is left running (``check_env`` resets many times).
- Made with ``gymnasium.make("objview/ObjView-v0", …)`` the environment is wrapped: its own
  attributes (``stop_action``, ``candidates``, ``episode``, ``result``, ``client``) are on
  ``env.unwrapped``.
"""

from __future__ import annotations

import json
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

import gymnasium
import numpy as np
from gymnasium import spaces

from .client import FROM_ENV, Client, Episode, Observation
from .errors import EpisodeFinished
from .types import Result

__all__ = ["ObjViewEnv"]

ObsDict = Dict[str, np.ndarray]
RewardFn = Callable[["ObjViewEnv", ObsDict, Dict[str, Any]], float]


class ObjViewEnv(gymnasium.Env[Dict[str, Any], Any]):
    """Gymnasium environment: one server episode per Gymnasium episode (see module docs)."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        url: Union[str, Client, None] = None,
        split: str = "main_hidden_test",
        view_space: str = "whole",
        budget: Union[int, str] = "auto",
        candidate_set: str = "tammes-360",
        method: str = "gym",
        family: str = "learned",
        seed: int = 0,
        token: Optional[str] = FROM_ENV,
        objects: Optional[Iterable[Union[int, str]]] = None,
        execution_mode: str = "iterative",
        params: Any = None,
        record_timings: bool = True,
        reward_fn: Optional[RewardFn] = None,
        render_mode: Optional[str] = None,
        timeout: float = 600.0,
        max_moves: Optional[int] = None,
        shard: Optional[Tuple[int, int]] = None,
    ):
        super().__init__()
        if isinstance(url, Client):
            self.client = url
        else:
            self.client = Client(FROM_ENV if url is None else url, token=token, timeout=timeout)
        self._own_client = not isinstance(url, Client)
        self.split = split
        self.view_space = view_space
        self.budget = budget
        self.candidate_set = candidate_set
        self.method = method
        self.family = family
        self.execution_mode = execution_mode
        self.params = params
        self.record_timings = record_timings
        self.reward_fn = reward_fn
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.base_seed = int(seed)
        if max_moves is not None and int(max_moves) < 1:
            raise ValueError(f"max_moves must be a positive integer or None, not {max_moves!r}")
        self.max_moves = None if max_moves is None else int(max_moves)

        info = self.client.split(split)
        self.object_ids: List[str] = list(info.get("object_ids") or [])
        cycle: List[Union[int, str]] = (
            list(objects) if objects is not None else list(range(int(info["objects"])))
        )
        self.shard = None if shard is None else (int(shard[0]), int(shard[1]))
        if self.shard is not None:
            i, n = self.shard
            if not (n >= 1 and 0 <= i < n):
                raise ValueError(f"shard must be (i, n) with 0 <= i < n, not {shard!r}")
            cycle = cycle[i::n]
        self._cycle = cycle
        if not self._cycle:
            raise ValueError(f"split {split!r} has no objects to cycle through (shard {shard})")
        self._cursor = 0

        self.candidates: np.ndarray = self.client.candidate_set(candidate_set)
        n_c = int(self.candidates.shape[0])
        self.num_candidates = n_c
        self.stop_action = n_c
        self.action_space = spaces.Discrete(n_c + 1)
        self.observation_space = spaces.Dict(
            {
                "depth": spaces.Box(0.0, np.inf, shape=(512, 512), dtype=np.float32),
                "pose": spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64),
                "mask": spaces.MultiBinary(n_c),
            }
        )
        self.episode: Optional[Episode] = None
        self._mask: Optional[np.ndarray] = None
        self._last: Optional[Observation] = None
        self._moves = 0

    # ------------------------------------------------------------------------------ reset
    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[ObsDict, Dict[str, Any]]:
        super().reset(seed=seed)
        self._abort_running("ObjViewEnv.reset() before the episode ended")
        if seed is not None:
            self.base_seed = int(seed) - (self.shard[0] if self.shard is not None else 0)
            self._cursor = 0
        options = options or {}
        if "object" in options:
            obj = options["object"]
        else:
            obj = self._cycle[self._cursor % len(self._cycle)]
            self._cursor += 1
        if isinstance(obj, np.integer):
            obj = int(obj)
        self.episode = self.client.create_episode(
            self.split,
            obj,
            view_space=self.view_space,
            budget=self.budget,
            method=self.method,
            family=self.family,
            execution_mode=self.execution_mode,
            candidate_set=self.candidate_set,
            seed=self.base_seed,
            params=self.params,
            record_timings=self.record_timings,
            eager_depth=True,
        )
        self._moves = 0
        self._mask = self.episode.feasible(self.candidates).astype(np.int8)
        self._last = self.episode.observation()
        obs = self._obs(self._last)
        info = self._info(self._last)
        info["intrinsics"] = dict(self.episode.intrinsics)
        info["candidates"] = np.array(self.candidates, dtype=np.float64, copy=True)
        return obs, info

    # ------------------------------------------------------------------------------- step
    def step(self, action: Any) -> Tuple[ObsDict, float, bool, bool, Dict[str, Any]]:
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        ep = self.episode
        if isinstance(action, np.ndarray) and action.shape == (7,):
            move: Optional[Any] = action
        else:
            try:
                idx = int(action)
            except (TypeError, ValueError):
                raise ValueError(
                    f"an action is a candidate index in [0, {self.stop_action}] or a pose array "
                    f"of shape (7,), not {action!r}"
                ) from None
            if idx != action or not 0 <= idx <= self.stop_action:
                raise ValueError(f"action index {action!r} outside [0, {self.stop_action}]")
            move = None if idx == self.stop_action else self.candidates[idx]
        try:
            if ep.done:  # stepping a finished episode: its end again
                o = ep.observation()
            elif move is None:
                o = ep.stop("plan_end")
            else:
                o = ep.move(move)
                self._moves += 1
                if not o.done and self.max_moves is not None and self._moves >= self.max_moves:
                    o = ep.stop("plan_end")
        except EpisodeFinished:
            # The server ended the episode (a time limit, a restart): report its end.
            o = ep.refresh()
        self._last = o
        obs = self._obs(o)
        info = self._info(o)
        if o.done:
            info["terminal"] = dict(o.terminal) if o.terminal else o.terminal
            info["result_json"] = json.dumps(ep.result())
        reward = 0.0 if self.reward_fn is None else float(self.reward_fn(self, obs, info))
        return obs, reward, bool(o.done), False, info

    @property
    def result(self) -> Optional[Result]:
        """The current episode's result once it ended (a dict), else None."""
        if self.episode is None or not self.episode.done:
            return None
        return self.episode.result()

    # ----------------------------------------------------------------------------- render
    def render(self) -> Optional[np.ndarray]:
        """``rgb_array``: the current view's RGB image from the server (uint8 (H, W, 3))."""
        if self.render_mode != "rgb_array" or self._last is None:
            return None
        return self._last.rgb()

    def close(self) -> None:
        """Abort the episode if it is still running (see the module docs); close the
        connections of a client the environment created."""
        self._abort_running("ObjViewEnv.close() before the episode ended")
        self.episode = None
        self._last = None
        if self._own_client:
            self.client.close()
        super().close()

    # ---------------------------------------------------------------------------- helpers
    def _abort_running(self, detail: str) -> None:
        ep = self.episode
        if ep is not None and not ep.done:
            ep._abort_quietly(detail)

    def _obs(self, o: Observation) -> ObsDict:
        assert self._mask is not None
        return {
            "depth": np.array(o.depth, dtype=np.float32, copy=True),
            "pose": np.array(o.pose, dtype=np.float64, copy=True),
            "mask": self._mask.copy(),
        }

    def _info(self, o: Observation) -> Dict[str, Any]:
        assert self.episode is not None and self._mask is not None
        return {
            "step": o.step,
            "object_id": self.episode.object_id,
            "action_mask": self.action_mask,
        }

    @property
    def action_mask(self) -> np.ndarray:
        """int8 (N + 1,): the candidates' feasibility, and 1 for the stop action (index N)."""
        assert self._mask is not None, "call reset() first"
        return np.concatenate([self._mask, np.ones(1, dtype=np.int8)])

    @property
    def feasible_mask(self) -> Optional[np.ndarray]:
        """The current episode's candidate feasibility (bool (N,)), or None before reset."""
        return None if self._mask is None else self._mask.astype(bool)


ENV_ID = "objview/ObjView-v0"


def register() -> None:
    """Register ``objview/ObjView-v0`` so that ``gymnasium.make("objview/ObjView-v0", url=…,
    split=…)`` works (``import objview`` does it)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="objview.gym:ObjViewEnv")


register()
