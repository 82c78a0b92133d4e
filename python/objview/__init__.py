"""Python client of the objview evaluation server (ObjView-Bench online episodes).

- :class:`Client`: the HTTP API v1 (``docs/server-api.md``): splits, view spaces, candidate
  sets, episodes, results.
- :class:`Episode` / :class:`Observation`: one episode's state; ``move``, ``stop``,
  ``feasible``; depth as a float32 (512, 512) array.
- :func:`run_planner`: the loop that runs a :class:`Planner` over a split.
- :mod:`objview.gym`: :class:`objview.gym.ObjViewEnv`, a Gymnasium environment (imported on
  demand so that the client works without importing gymnasium).
- :mod:`objview.learn`: the reader of the oracle training data that ``objview learn dataset``
  writes (numpy only): :class:`objview.learn.CaseDataset`, :func:`objview.learn.iter_batches`.
- Errors: :class:`ServerError` and its subclasses, one per error code of the contract.
"""

from . import learn
from .client import STOP_REASONS, Client, Episode, Observation, pose_to_json
from .errors import (
    EpisodeFinished,
    EpisodeRunning,
    InvalidRequest,
    MalformedJSON,
    MethodNotAllowed,
    NotFound,
    ObjViewError,
    PayloadTooLarge,
    ServerError,
    StaleStep,
    TransportError,
    Unauthorized,
)
from .planner import Planner, run_episode, run_planner

__version__ = "0.1.0"

__all__ = [
    "Client",
    "Episode",
    "Observation",
    "Planner",
    "run_planner",
    "run_episode",
    "pose_to_json",
    "STOP_REASONS",
    "ObjViewError",
    "TransportError",
    "ServerError",
    "MalformedJSON",
    "Unauthorized",
    "NotFound",
    "MethodNotAllowed",
    "StaleStep",
    "EpisodeFinished",
    "EpisodeRunning",
    "PayloadTooLarge",
    "InvalidRequest",
    "learn",
]
