"""Python client of the objview evaluation server (ObjView-Bench online episodes).

- :class:`Client`: the HTTP API v1 (``docs/server-api.md``): splits, view spaces, candidate
  sets, episodes, results.
- :class:`Episode` / :class:`Observation`: one episode's state; ``move``, ``stop``,
  ``feasible``; depth as a float32 (512, 512) array.
- :func:`run_planner`: the loop that runs a :class:`Planner` over a split.
- :mod:`objview.gym`: :class:`objview.gym.ObjViewEnv`, a Gymnasium environment (the module is
  imported on demand; ``import objview`` registers ``objview/ObjView-v0`` with gymnasium, so
  ``gymnasium.make("objview/ObjView-v0", url=…, split=…)`` works after it).
- :mod:`objview.camera`: the camera of SPEC §2 — axes, projection, back-projection;
  :mod:`objview.types`: TypedDicts of the JSON documents (the package ships ``py.typed``).
- :mod:`objview.learn`: the reader of the oracle training data that ``objview learn dataset``
  writes (numpy only): :class:`objview.learn.CaseDataset`, :func:`objview.learn.iter_batches`.
- Errors: :class:`ServerError` and its subclasses, one per error code of the contract.
"""

import logging

from . import camera, learn, types
from .client import (
    STOP_REASONS,
    Client,
    Episode,
    Observation,
    Response,
    check_stop_reason,
    pose_to_json,
)
from .errors import (
    EpisodeFinished,
    EpisodeRunning,
    InvalidRequest,
    MalformedJSON,
    MethodNotAllowed,
    NotFound,
    ObjViewError,
    Overloaded,
    PayloadTooLarge,
    RequestTimeout,
    ServerError,
    StaleStep,
    TooManyEpisodes,
    TransportError,
    Unauthorized,
)
from .planner import Planner, run_episode, run_planner, summary_line

__version__ = "0.1.0"

# A library logs, the application decides where it goes (nothing is printed by default).
logging.getLogger(__name__).addHandler(logging.NullHandler())


def _register_env() -> None:
    """Register ``objview/ObjView-v0`` with gymnasium without importing :mod:`objview.gym`."""
    try:
        import gymnasium
    except ImportError:  # pragma: no cover - gymnasium is a dependency; the client works without
        return
    if "objview/ObjView-v0" not in gymnasium.registry:
        gymnasium.register(id="objview/ObjView-v0", entry_point="objview.gym:ObjViewEnv")


_register_env()

__all__ = [
    "Client",
    "Episode",
    "Observation",
    "Response",
    "check_stop_reason",
    "summary_line",
    "camera",
    "types",
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
    "RequestTimeout",
    "TooManyEpisodes",
    "Overloaded",
    "learn",
]
