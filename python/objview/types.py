"""Typed shapes of the server's JSON documents (``docs/server-api.md``), for type checkers.

They are :class:`typing.TypedDict` classes: at run time the values are plain ``dict`` objects,
so ``res["checkpoints"]["K=5"]`` works as before; a type checker (mypy, pyright) checks the
keys.  ``total=False`` marks documents whose keys depend on the run (a result line has more
keys than listed; the listed ones are those the contract names).
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, TypedDict

__all__ = [
    "Checkpoint",
    "EpisodeSummary",
    "Intrinsics",
    "ObservationMeta",
    "Result",
    "Terminal",
]


class Intrinsics(TypedDict):
    """The pinhole camera of a view (SPEC §2): image size, focal lengths and principal point in
    pixels, near/far clipping distances along the camera z axis in object units."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    znear: float
    zfar: float


class Terminal(TypedDict):
    """Why an episode ended: ``source`` (``algorithm_stop``, ``benchmark``, ``exception``),
    ``reason`` (e.g. ``plan_end``, ``enough_info``, ``invalid_action``, ``timeout``,
    ``planner_error``) and ``detail`` (free text or None)."""

    source: str
    reason: str
    detail: Optional[str]


class ObservationMeta(TypedDict, total=False):
    """OBS of the contract: an observation's metadata."""

    step: int
    pose: List[float]
    intrinsics: Intrinsics
    done: bool
    terminal: Optional[Terminal]


class Checkpoint(TypedDict, total=False):
    """One checkpoint of a result (``K=5``, ``MS@0.02``, ``terminal``…)."""

    views: int
    sc: Dict[str, float]
    nsc: Dict[str, float]
    cd: Any
    path_cost: float
    runtime: Any


class Result(TypedDict, total=False):
    """One finished episode: a line of ``objview run``'s JSON Lines (the keys named by the
    contract; the line has more)."""

    uid: str
    method: str
    family: str
    execution_mode: str
    view_space: str
    budget: Any
    seed: int
    start_pose: List[float]
    visited_poses: List[List[float]]
    terminal_source: str
    terminal_reason: str
    terminal_detail: Optional[str]
    steps: List[Dict[str, Any]]
    checkpoints: Dict[str, Checkpoint]
    settings: Dict[str, Any]
    params: Any
    error: str


class EpisodeSummary(TypedDict):
    """One entry of ``GET /v1/episodes`` (:meth:`objview.Client.list_episodes`)."""

    episode_id: str
    split: str
    object: str
    method: str
    state: str
    step: int
    created_at: Any
