"""A Gymnasium environment over the objview evaluation server.

    from objview.gym import ObjViewEnv
    env = ObjViewEnv("http://127.0.0.1:8080", split="main_hidden_test", budget=5)
    obs, info = env.reset(seed=0)
    while True:
        obs, reward, terminated, truncated, info = env.step(agent(obs))
        if terminated:
            print(info["result"]["checkpoints"]["K=5"])
            break

One Gymnasium episode is one server episode.

- **Actions**: ``Discrete(N + 1)`` — an index ``i < N`` moves the camera to candidate ``i`` of the
  candidate set (``candidate_set``, default tammes-360, N = 360); ``N`` stops the episode with
  reason ``plan_end``.  ``step`` also accepts a continuous pose, a numpy array of shape (7,)
  ``[cx, cy, cz, lx, ly, lz, roll]`` (SPEC §2); it is outside ``action_space`` (which stays
  Discrete so that standard agents work) but a feasible continuous pose is a legal benchmark
  action.
- **Observations**: ``{"depth": float32 (512, 512) camera-frame z (0 = no hit),
  "pose": float64 (7,), "mask": int8 (N,)}``.  ``mask[i] = 1`` when candidate ``i`` is feasible
  in the episode's view space.  It is queried once per episode (one batch request at reset) and
  does not change during the episode: **visited candidates are not masked out** (SPEC §5 allows
  repeated poses: they are rendered, counted and cost zero path), so an agent that must not
  repeat views keeps its own record.  An infeasible index is sent as it is and ends the episode
  with ``invalid_action`` (the benchmark's rule), so agents should respect the mask.
- **Reward**: 0.0 at every step.  The benchmark hides every metric of a running episode (the
  object is hidden; coverage, CD and anything derived from the ground truth appear only in the
  result, after the end), so no dense reward can be computed honestly on a hidden split.  The
  final result is in ``info["result"]`` at termination; pass ``reward_fn(env, obs, info)`` to
  compute your own reward (e.g. from ``info["result"]`` at the end, or from the depth images).
- ``terminated`` is True when the server ended the episode (the planner's stop, a budget, the
  cap, ``enough_info``, an invalid action, a timeout); ``truncated`` is always False (the server
  owns every limit).  ``info``: ``step`` and ``object_id`` always; at the end ``result`` (the
  ``objview run`` JSON line as a dict) and ``terminal`` (``{"source", "reason", "detail"}``).
- **Objects**: without ``objects`` the environment cycles through every object of the split, one
  per ``reset``; ``objects`` restricts (and orders) that cycle (indices or uids);
  ``reset(options={"object": i})`` picks one explicitly.  ``reset(seed=s)`` restarts the cycle at
  its first object and makes ``s`` the benchmark seed of the following episodes, so the same
  seed gives the same episode (Gymnasium's determinism rule).
- An episode that is still running when ``reset`` or ``close`` is called is left to the server,
  which ends it after its action timeout (source ``exception``, reason ``timeout``): the
  environment never stops an episode on the agent's behalf, because a stop is scored as the
  planner's own decision.
"""

from __future__ import annotations

from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

import gymnasium
import numpy as np
from gymnasium import spaces

from .client import Client, Episode, Observation

__all__ = ["ObjViewEnv"]

RewardFn = Callable[["ObjViewEnv", Dict[str, Any], Dict[str, Any]], float]


class ObjViewEnv(gymnasium.Env):
    """Gymnasium environment: one server episode per Gymnasium episode (see module docs)."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        url: Union[str, Client],
        split: str,
        view_space: str = "whole",
        budget: Union[int, str] = "auto",
        candidate_set: str = "tammes-360",
        method: str = "gym",
        family: str = "learned",
        seed: int = 0,
        token: Optional[str] = None,
        objects: Optional[Iterable[Union[int, str]]] = None,
        execution_mode: str = "iterative",
        params: Any = None,
        record_timings: bool = True,
        reward_fn: Optional[RewardFn] = None,
        render_mode: Optional[str] = None,
        timeout: float = 600.0,
    ):
        super().__init__()
        self.client = url if isinstance(url, Client) else Client(url, token=token, timeout=timeout)
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

        info = self.client.split(split)
        self.object_ids: List[str] = list(info.get("object_ids") or [])
        self._cycle: List[Union[int, str]] = (
            list(objects) if objects is not None else list(range(int(info["objects"])))
        )
        if not self._cycle:
            raise ValueError(f"split {split!r} has no objects to cycle through")
        self._cursor = 0

        self.candidates: np.ndarray = self.client.candidate_set(candidate_set)
        n = int(self.candidates.shape[0])
        self.num_candidates = n
        self.stop_action = n
        self.action_space = spaces.Discrete(n + 1)
        self.observation_space = spaces.Dict(
            {
                "depth": spaces.Box(0.0, np.inf, shape=(512, 512), dtype=np.float32),
                "pose": spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64),
                "mask": spaces.MultiBinary(n),
            }
        )
        self.episode: Optional[Episode] = None
        self._mask: Optional[np.ndarray] = None
        self._last: Optional[Observation] = None

    # ------------------------------------------------------------------------------ reset
    def reset(
        self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
    ) -> Tuple[Dict[str, np.ndarray], Dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            self.base_seed = int(seed)
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
        self._mask = self.episode.feasible(self.candidates).astype(np.int8)
        self._last = self.episode.observation()
        obs = self._obs(self._last)
        info = self._info(self._last)
        return obs, info

    # ------------------------------------------------------------------------------- step
    def step(self, action: Any):
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        ep = self.episode
        if isinstance(action, np.ndarray) and action.shape == (7,):
            o = ep.move(action)
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
            if idx == self.stop_action:
                o = ep.stop("plan_end")
            else:
                o = ep.move(self.candidates[idx])
        self._last = o
        obs = self._obs(o)
        info = self._info(o)
        if o.done:
            info["terminal"] = dict(o.terminal) if o.terminal else o.terminal
            info["result"] = ep.result()
        reward = 0.0 if self.reward_fn is None else float(self.reward_fn(self, obs, info))
        return obs, reward, bool(o.done), False, info

    # ----------------------------------------------------------------------------- render
    def render(self):
        """``rgb_array``: the current view's RGB image from the server (uint8 (H, W, 3))."""
        if self.render_mode != "rgb_array" or self._last is None:
            return None
        return self._last.rgb()

    def close(self):
        self.episode = None
        self._last = None
        super().close()

    # ---------------------------------------------------------------------------- helpers
    def _obs(self, o: Observation) -> Dict[str, np.ndarray]:
        assert self._mask is not None
        return {
            "depth": np.array(o.depth, dtype=np.float32, copy=True),
            "pose": np.array(o.pose, dtype=np.float64, copy=True),
            "mask": self._mask.copy(),
        }

    def _info(self, o: Observation) -> Dict[str, Any]:
        assert self.episode is not None
        return {"step": o.step, "object_id": self.episode.object_id}

    @property
    def feasible_mask(self) -> Optional[np.ndarray]:
        """The current episode's candidate feasibility (bool (N,)), or None before reset."""
        return None if self._mask is None else self._mask.astype(bool)


def _register() -> None:
    """Register ``objview/ObjView-v0`` so that ``gymnasium.make("objview/ObjView-v0", url=…,
    split=…)`` works."""
    try:
        if "objview/ObjView-v0" not in gymnasium.registry:
            gymnasium.register(id="objview/ObjView-v0", entry_point="objview.gym:ObjViewEnv")
    except Exception:  # pragma: no cover - registration is a convenience only
        pass


_register()
