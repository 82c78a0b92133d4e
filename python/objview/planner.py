"""The planner loop: run a Python planner over a split of the server, one episode per object.

A planner is any object with two methods (subclassing :class:`Planner` is optional):

- ``reset(episode)``: a new episode starts (``episode.seed``, ``episode.candidates``,
  ``episode.intrinsics``, ``episode.feasible(poses)``, ``episode.fixed_budget`` …);
- ``act(observation, episode)`` → ``("move", pose)`` or ``("stop", reason)`` (a dict ACTION
  of the HTTP contract, ``{"type": "move", "pose": …}``, is accepted too).

The server ends the episode (budget checkpoints, cap, ``enough_info``, an invalid action, a
timeout); the loop stops when it does and collects the result.
"""

from __future__ import annotations

import sys
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

from .client import Client, Episode, Observation, iter_objects, pose_to_json

__all__ = ["Planner", "run_planner", "run_episode", "action_to_json"]

Action = Union[Tuple[str, Any], Dict[str, Any]]


class Planner:
    """Base class of a planner (optional: duck typing is enough)."""

    #: Recorded as the result's ``family`` unless run_planner is given one.
    family: str = "classical"
    #: Recorded as the result's ``execution_mode`` unless run_planner is given one.
    execution_mode: str = "iterative"

    def reset(self, episode: Episode) -> None:
        """Called once per episode, before the first :meth:`act`."""

    def act(self, observation: Observation, episode: Episode) -> Action:
        """Return ``("move", pose)`` or ``("stop", reason)``."""
        raise NotImplementedError


def action_to_json(action: Action) -> Dict[str, Any]:
    """A planner's action as the contract's ACTION object."""
    if isinstance(action, dict):
        return action
    if isinstance(action, (tuple, list)) and len(action) == 2:
        kind, arg = action
        if kind == "move":
            return {"type": "move", "pose": pose_to_json(arg)}
        if kind == "stop":
            return {"type": "stop", "reason": arg}
    raise ValueError(f"a planner action is ('move', pose) or ('stop', reason), not {action!r}")


def run_episode(planner: Any, episode: Episode) -> Dict[str, Any]:
    """Drive one created episode with ``planner`` until the server ends it; return the result."""
    planner.reset(episode)
    obs = episode.observation()
    while not obs.done:
        obs = episode.act(action_to_json(planner.act(obs, episode)))
    return episode.result()


def run_planner(
    client: Client,
    planner: Any,
    split: str,
    objects: Optional[Iterable[Union[int, str]]] = None,
    view_space: str = "whole",
    budget: Union[int, str] = "auto",
    method: Optional[str] = None,
    family: Optional[str] = None,
    execution_mode: Optional[str] = None,
    candidate_set: str = "tammes-360",
    seed: int = 0,
    params: Any = None,
    record_timings: bool = True,
    eager_depth: bool = True,
    progress: Union[bool, Callable[[int, Dict[str, Any]], None]] = False,
) -> List[Dict[str, Any]]:
    """Run ``planner`` on every object of ``split`` (or the given indices/uids), one episode
    each, sequentially; return the result dicts in object order.

    ``method`` defaults to the planner's ``name`` attribute or its class name; ``family`` and
    ``execution_mode`` to the planner's attributes of those names (else ``classical`` /
    ``iterative``).  ``eager_depth=False`` skips downloading depth images the planner never
    reads (it is still fetched on access of ``observation.depth``).  ``progress``: True prints
    one line per episode to stderr; a callable gets ``(index, result)``.

    An exception in the planner propagates; its episode is left to the server, which ends it
    after the action timeout (source ``exception``, reason ``timeout``, views scored).
    """
    if method is None:
        method = getattr(planner, "name", None) or type(planner).__name__
    if family is None:
        family = getattr(planner, "family", "classical")
    if execution_mode is None:
        execution_mode = getattr(planner, "execution_mode", "iterative")
    results = []
    for i, obj in enumerate(iter_objects(client, split, objects)):
        ep = client.create_episode(
            split,
            obj,
            view_space=view_space,
            budget=budget,
            method=method,
            family=family,
            execution_mode=execution_mode,
            candidate_set=candidate_set,
            seed=seed,
            params=params,
            record_timings=record_timings,
            eager_depth=eager_depth,
        )
        res = run_episode(planner, ep)
        results.append(res)
        if callable(progress):
            progress(i, res)
        elif progress:
            print(summary_line(res), file=sys.stderr, flush=True)
    return results


def summary_line(res: Dict[str, Any]) -> str:
    """One line about a result: uid, views, SC/NSC@0.02 at the terminal checkpoint, reason."""
    cp = (res.get("checkpoints") or {}).get("terminal") or {}
    sc = (cp.get("sc") or {}).get("0.02")
    nsc = (cp.get("nsc") or {}).get("0.02")
    fmt = lambda x: "-" if x is None else f"{x:.3f}"  # noqa: E731
    return (
        f"{res.get('uid')}: {cp.get('views')} views, NSC@0.02 {fmt(nsc)}, SC@0.02 {fmt(sc)}, "
        f"path {fmt(cp.get('path_cost'))}, {res.get('terminal_reason')} "
        f"({res.get('terminal_source')})"
    )
