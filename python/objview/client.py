"""HTTP client of the objview evaluation server (``objview serve``).

The contract is ``docs/server-api.md`` of the objview repository (API v1).  Only the standard
library (``http.client``) and numpy are used.

    import objview
    client = objview.Client("http://127.0.0.1:8080", token="my-token")
    with client.create_episode("main_hidden_test", 0, budget=5, method="my-nbv") as ep:
        obs = ep.observation()                  # step 0: the start view
        for _ in range(5):
            obs = ep.move(next_pose(obs))
        ep.stop("plan_end")
    print(ep.result()["checkpoints"]["K=5"])

Transport: one persistent HTTP/1.1 connection per thread and client (keep-alive), responses
compressed with gzip when the server offers it.  A :class:`Client` may be shared by threads
(each thread gets its own connection); an :class:`Episode` belongs to one thread at a time.
"""

from __future__ import annotations

import gzip
import http.client
import io
import json
import logging
import math
import os
import threading
import urllib.parse
from types import TracebackType
from typing import (
    Any,
    Dict,
    Iterable,
    List,
    Optional,
    Sequence,
    Type,
    Union,
    cast,
)

import numpy as np

from . import camera
from ._png import decode_png
from .errors import EpisodeFinished, ServerError, TransportError, error_from_response
from .types import EpisodeSummary, Intrinsics, ObservationMeta, Result, Terminal

logger = logging.getLogger(__name__)

__all__ = ["Client", "Episode", "Observation", "STOP_REASONS", "pose_to_json"]

#: The stop reasons of SPEC §5 (anything else ends the episode with ``invalid_action``).
STOP_REASONS = ("plan_end", "candidate_exhausted", "next_view_visited", "next_view_infeasible")

#: Largest batch of one feasibility request (the contract's limit).
MAX_FEASIBLE_BATCH = 4_096
#: Largest JSON body of one feasibility request this client sends (the server's limit is 1 MiB).
MAX_FEASIBLE_BYTES = 768 * 1024

PoseLike = Union[Sequence[float], np.ndarray]


def pose_to_json(pose: Any) -> Any:
    """A pose as JSON-ready numbers.

    Numbers are sent as Python floats (``repr`` round-trips float64 exactly).  JSON has no NaN or
    infinity: a non-finite number is sent as ``null``, which the server treats as "not 7 finite
    numbers" — a malformed action that ends the episode with ``invalid_action`` (SPEC §5), the
    same outcome a local run gives.  Anything that is not a sequence of numbers is sent as it is
    (the server decides).
    """
    if isinstance(pose, np.ndarray):
        pose = pose.tolist()
    if isinstance(pose, (list, tuple)):
        out: List[Any] = []
        for x in pose:
            if isinstance(x, (bool, np.bool_)):
                out.append(x)
            elif isinstance(x, (int, float, np.integer, np.floating)):
                f = float(x)
                out.append(f if math.isfinite(f) else None)
            else:
                out.append(x)
        return out
    return pose


def _poses_array(poses: Any) -> np.ndarray:
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    return arr


#: Default server URL when neither ``url`` nor ``$OBJVIEW_URL`` is given.
DEFAULT_URL = "http://127.0.0.1:8080"


class _FromEnv:
    """The default of :class:`Client`'s ``url``/``token``: read the environment variable."""

    def __repr__(self) -> str:
        return "<from the environment>"


FROM_ENV: Any = _FromEnv()

# Errors of a reused keep-alive connection that the server closed while it was idle: the request
# was not read, so it is sent again once on a new connection.
_STALE_CONNECTION = (
    http.client.RemoteDisconnected,
    http.client.BadStatusLine,
    ConnectionResetError,
    ConnectionAbortedError,
    BrokenPipeError,
)


def check_stop_reason(reason: Any) -> str:
    """``reason`` if it is one of :data:`STOP_REASONS`, else :class:`ValueError` (a typo would
    otherwise reach the server and end the episode with ``invalid_action``)."""
    if not isinstance(reason, str) or reason not in STOP_REASONS:
        raise ValueError(f"unknown stop reason {reason!r}: one of {', '.join(STOP_REASONS)}")
    return reason


class Client:
    """A connection to an objview evaluation server.

    ``url``: the server's base URL (``http://host:port``, a path prefix is kept); default
    ``$OBJVIEW_URL``, else ``http://127.0.0.1:8080``.  ``token``: the bearer token when the server
    was started with ``--tokens``; default ``$OBJVIEW_TOKEN`` (unset: no token); pass
    ``token=None`` to send none whatever the environment says.  ``timeout``: seconds per request
    (creating an episode may take seconds the first time an object is used).

    Thread-safe: every thread that uses the client gets its own persistent (keep-alive)
    connection; :meth:`close` closes them all.  Responses are asked for with
    ``Accept-Encoding: gzip`` and decoded.
    """

    def __init__(self, url: Any = FROM_ENV, token: Any = FROM_ENV, timeout: float = 600.0):
        if url is FROM_ENV or url is None:
            url = os.environ.get("OBJVIEW_URL") or DEFAULT_URL
        if token is FROM_ENV:
            token = os.environ.get("OBJVIEW_TOKEN") or None
        self.url: str = str(url).rstrip("/")
        self.token: Optional[str] = token
        self.timeout = timeout
        parts = urllib.parse.urlsplit(self.url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"the server URL must be http://host[:port][/prefix], not {url!r}")
        self._scheme = parts.scheme
        self._host = parts.hostname
        self._port = parts.port
        self._prefix = parts.path.rstrip("/")
        self._candidate_cache: Dict[str, np.ndarray] = {}
        self._lock = threading.Lock()
        self._local = threading.local()
        self._connections: List[http.client.HTTPConnection] = []
        #: Connections opened so far (a new one per thread, and after the server closed one).
        self.connections_opened = 0

    def __repr__(self) -> str:
        return f"objview.Client({self.url!r})"

    def __deepcopy__(self, memo: Dict[int, Any]) -> "Client":
        # A client is shared, never copied (planners copied per worker keep the same client).
        return self

    def __getstate__(self) -> Dict[str, Any]:
        st = dict(self.__dict__)
        for k in ("_lock", "_local", "_connections"):
            st.pop(k, None)
        return st

    def __setstate__(self, st: Dict[str, Any]) -> None:
        self.__dict__.update(st)
        self._lock = threading.Lock()
        self._local = threading.local()
        self._connections = []

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Close every connection of this client (a later request opens a new one)."""
        with self._lock:
            conns, self._connections = self._connections, []
        for c in conns:
            c.close()
        self._local = threading.local()

    # ----------------------------------------------------------------------------- transport
    def _connection(self) -> http.client.HTTPConnection:
        conn: Optional[http.client.HTTPConnection] = getattr(self._local, "conn", None)
        if conn is None:
            if self._scheme == "https":
                conn = http.client.HTTPSConnection(self._host, self._port, timeout=self.timeout)
            else:
                conn = http.client.HTTPConnection(self._host, self._port, timeout=self.timeout)
            self._local.conn = conn
            with self._lock:
                self._connections.append(conn)
        return conn

    def _drop_connection(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None
            with self._lock:
                if conn in self._connections:
                    self._connections.remove(conn)

    def request(
        self,
        method: str,
        path: str,
        body: Any = None,
        query: Optional[Dict[str, Any]] = None,
        raw_body: Optional[bytes] = None,
    ) -> "Response":
        """Send one request; return the :class:`Response` or raise a :class:`ServerError`.

        ``body`` is sent as JSON; ``raw_body`` as it is (with a JSON content type), for tests.
        The response's ``content`` is decoded (gzip); its ``headers`` are as received.
        """
        target = self._prefix + path
        if query:
            target += "?" + urllib.parse.urlencode(query)
        headers = {"Accept": "application/json", "Accept-Encoding": "gzip"}
        data = None
        if raw_body is not None:
            data = raw_body
        elif body is not None:
            data = json.dumps(body, allow_nan=False).encode("utf-8")
        if data is not None:
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        for attempt in (0, 1):
            conn = self._connection()
            fresh = conn.sock is None
            if fresh:
                with self._lock:
                    self.connections_opened += 1
            try:
                conn.request(method, target, body=data, headers=headers)
                resp = conn.getresponse()
                raw = resp.read()
            except _STALE_CONNECTION as e:
                self._drop_connection()
                if attempt == 0 and not fresh:
                    logger.debug("%s %s: the kept-alive connection was closed (%s); reconnecting",
                                 method, target, e)
                    continue
                raise TransportError(f"{method} {self.url}{path}: {e!r}") from e
            except (OSError, http.client.HTTPException) as e:
                self._drop_connection()
                raise TransportError(f"{method} {self.url}{path}: {e!r}") from e
            if resp.will_close:
                self._drop_connection()
            break
        hdrs = dict(resp.getheaders())
        enc = (resp.getheader("Content-Encoding") or "").strip().lower()
        if enc == "gzip":
            try:
                raw = gzip.decompress(raw)
            except (OSError, EOFError) as e:
                raise TransportError(f"{method} {path}: bad gzip body: {e}") from e
        elif enc not in ("", "identity"):
            raise TransportError(f"{method} {path}: unsupported Content-Encoding {enc!r}")
        if resp.status >= 400:
            raise error_from_response(resp.status, raw)
        return Response(resp.status, hdrs, raw)

    def _json(
        self, method: str, path: str, body: Any = None, query: Optional[Dict[str, Any]] = None
    ) -> Any:
        resp = self.request(method, path, body=body, query=query)
        try:
            return json.loads(resp.content.decode("utf-8"))
        except ValueError as e:
            raise TransportError(f"{method} {path}: the answer is not JSON: {e}") from e

    @staticmethod
    def _seg(s: Any) -> str:
        return urllib.parse.quote(str(s), safe="")

    # ----------------------------------------------------------------------------- catalogue
    def health(self) -> Dict[str, Any]:
        """``GET /v1/health`` → ``{"status": "ok", "version": ...}``."""
        return cast(Dict[str, Any], self._json("GET", "/v1/health"))

    def openapi(self) -> Dict[str, Any]:
        """``GET /openapi.json``: the server's OpenAPI 3.0 document."""
        return cast(Dict[str, Any], self._json("GET", "/openapi.json"))

    def splits(self) -> List[Dict[str, Any]]:
        """``GET /v1/splits`` → ``[{"id", "objects", "public"}, …]``."""
        return cast(List[Dict[str, Any]], self._json("GET", "/v1/splits")["splits"])

    def split(self, split_id: str) -> Dict[str, Any]:
        """``GET /v1/splits/{split}`` → ``{"id", "objects", "public", "object_ids"}``."""
        return cast(Dict[str, Any], self._json("GET", f"/v1/splits/{self._seg(split_id)}"))

    def view_spaces(self) -> List[str]:
        """``GET /v1/view-spaces`` → e.g. ``["whole", "hemi", "quarter", "eighth"]``."""
        return cast(List[str], self._json("GET", "/v1/view-spaces")["view_spaces"])

    def candidate_sets(self) -> List[str]:
        """``GET /v1/candidate-sets`` → e.g. ``["tammes-128", "tammes-360"]``."""
        return cast(List[str], self._json("GET", "/v1/candidate-sets")["candidate_sets"])

    def candidate_set(self, name: str) -> np.ndarray:
        """``GET /v1/candidate-sets/{name}`` → float64 array (N, 7) of poses (cached).

        The returned array is a read-only view of the cache; copy it to modify it.
        """
        with self._lock:
            got = self._candidate_cache.get(name)
        if got is None:
            doc = self._json("GET", f"/v1/candidate-sets/{self._seg(name)}")
            arr = np.asarray(doc["poses"], dtype=np.float64).reshape(-1, 7)
            arr.setflags(write=False)
            with self._lock:
                got = self._candidate_cache.setdefault(name, arr)
        return got

    def methods(self) -> List[Dict[str, Any]]:
        """``GET /v1/methods`` → ``[{"method", "finished"}, …]``."""
        return cast(List[Dict[str, Any]], self._json("GET", "/v1/methods")["methods"])

    def results(self, method: str) -> List[Result]:
        """``GET /v1/methods/{method}/results``: every finished result of ``method`` (the
        ``objview run`` JSON Lines format, ordered by finish time) as a list of dicts."""
        resp = self.request("GET", f"/v1/methods/{self._seg(method)}/results")
        text = resp.content.decode("utf-8")
        return [cast(Result, json.loads(line)) for line in text.splitlines() if line.strip()]

    def results_jsonl(self, method: str) -> str:
        """The raw JSON Lines text of :meth:`results` (``objview report`` reads it)."""
        resp = self.request("GET", f"/v1/methods/{self._seg(method)}/results")
        return resp.content.decode("utf-8")

    # ------------------------------------------------------------------------------ episodes
    def list_episodes(
        self, state: Optional[str] = None, method: Optional[str] = None
    ) -> List[EpisodeSummary]:
        """``GET /v1/episodes[?state=running|finished][&method=M]``: this token's episodes, as
        ``{"episode_id", "split", "object", "method", "state", "step", "created_at"}``."""
        if state is not None and state not in ("running", "finished"):
            raise ValueError(f"state must be 'running', 'finished' or None, not {state!r}")
        q: Dict[str, Any] = {}
        if state is not None:
            q["state"] = state
        if method is not None:
            q["method"] = method
        eps = self._json("GET", "/v1/episodes", query=q or None)["episodes"]
        # Filtered here too, so that the answer is right whatever the server does with them.
        return [
            e
            for e in eps
            if (state is None or e.get("state") == state)
            and (method is None or e.get("method") == method)
        ]

    def abort(self, episode_id: str, detail: Optional[str] = None) -> Dict[str, Any]:
        """``POST /v1/episodes/{id}/abort``: end a running episode as a planner failure
        (source ``exception``, reason ``planner_error``, ``detail`` recorded; the views taken are
        scored).  An episode that already ended → :class:`objview.EpisodeFinished`."""
        body: Dict[str, Any] = {} if detail is None else {"detail": str(detail)[:1000]}
        return cast(
            Dict[str, Any],
            self._json("POST", f"/v1/episodes/{self._seg(episode_id)}/abort", body=body),
        )

    def abort_orphans(
        self, method: Optional[str] = None, detail: str = "orphan: aborted by Client.abort_orphans"
    ) -> List[str]:
        """Abort every running episode of this token (of ``method`` only, when given) — the
        episodes a crashed or interrupted client left behind; return their ids.

        Call it when none of your runs with this token (and method) is in progress: it cannot
        tell an abandoned episode from one another process is playing.
        """
        aborted = []
        for e in self.list_episodes(state="running", method=method):
            try:
                self.abort(e["episode_id"], detail)
            except EpisodeFinished:
                continue  # ended meanwhile (its own end, or a time limit)
            logger.info("aborted orphan episode %s (%s)", e["episode_id"], e.get("method"))
            aborted.append(e["episode_id"])
        return aborted

    def create_episode(
        self,
        split: str,
        object: Union[int, str],
        view_space: str = "whole",
        budget: Union[int, str] = "auto",
        method: str = "python",
        family: str = "classical",
        execution_mode: str = "iterative",
        candidate_set: str = "tammes-360",
        seed: int = 0,
        params: Any = None,
        record_timings: bool = True,
        eager_depth: bool = True,
    ) -> "Episode":
        """``POST /v1/episodes``: start an episode (the server takes the start view).

        ``object``: an index into the split or a uid.  ``budget``: ``"auto"`` or a positive
        integer.  ``family`` ∈ {classical, learned, hybrid, baseline}; ``execution_mode`` ∈
        {iterative, budgeted_plan, set_cover_plan}.  ``seed`` is the base seed (the server mixes
        it per object, view space and budget into :attr:`Episode.seed`).  ``eager_depth``: fetch
        each observation's depth as soon as the observation exists (else on first access of
        :attr:`Observation.depth`, which must then happen before the next action).
        """
        if isinstance(object, (np.integer,)):
            object = int(object)
        if isinstance(budget, (np.integer,)):
            budget = int(budget)
        body = {
            "split": split,
            "object": object,
            "view_space": view_space,
            "budget": budget,
            "method": method,
            "family": family,
            "execution_mode": execution_mode,
            "candidate_set": candidate_set,
            "seed": int(seed),
            "params": {} if params is None else params,
            "record_timings": bool(record_timings),
        }
        doc = self._json("POST", "/v1/episodes", body=body)
        return Episode(self, doc, method=method, eager_depth=eager_depth)

    def episode(self, episode_id: str, eager_depth: bool = True) -> "Episode":
        """Attach to an existing episode by id (e.g. after a client restart)."""
        st = self.episode_status(episode_id)
        if st.get("state") == "finished":
            obs = {
                "step": st.get("step"),
                "pose": (st.get("history") or [None])[-1],
                "done": True,
                "terminal": st.get("terminal"),
            }
        else:
            obs = self.observation_meta(episode_id)
        doc = dict(st)
        doc["observation"] = obs
        return Episode(self, doc, method=st.get("method"), eager_depth=eager_depth)

    def episode_status(self, episode_id: str) -> Dict[str, Any]:
        """``GET /v1/episodes/{id}``."""
        return cast(Dict[str, Any], self._json("GET", f"/v1/episodes/{self._seg(episode_id)}"))

    def observation_meta(self, episode_id: str) -> Dict[str, Any]:
        """``GET /v1/episodes/{id}/observation`` → ``{"step", "pose", "done", "terminal"}``."""
        return cast(Dict[str, Any], self._json("GET", f"/v1/episodes/{self._seg(episode_id)}/observation"))

    def depth(self, episode_id: str, step: Optional[int] = None) -> np.ndarray:
        """``GET …/observation/depth.npy[?step=N]`` → float32 array (512, 512).

        With ``step``, a step that is not current raises :class:`objview.StaleStep`.
        """
        q = None if step is None else {"step": int(step)}
        resp = self.request(
            "GET", f"/v1/episodes/{self._seg(episode_id)}/observation/depth.npy", query=q
        )
        if step is not None:
            hdr = resp.header("X-Objview-Step")
            if hdr is not None and int(hdr) != int(step):
                raise TransportError(f"asked for the depth of step {step}, got step {hdr}")
        arr = np.load(io.BytesIO(resp.content), allow_pickle=False)
        return np.ascontiguousarray(arr, dtype=np.float32)

    def rgb_png(self, episode_id: str, step: Optional[int] = None) -> bytes:
        """``GET …/observation/rgb.png[?step=N]`` → the PNG bytes of the current view."""
        q = None if step is None else {"step": int(step)}
        resp = self.request(
            "GET", f"/v1/episodes/{self._seg(episode_id)}/observation/rgb.png", query=q
        )
        return resp.content

    def feasible(self, episode_id: str, poses: Any) -> np.ndarray:
        """``POST /v1/episodes/{id}/feasible`` → bool array (M,).

        Any number of poses: they are sent in batches of at most 4096 poses (the contract's
        limit) and well under the 1 MiB body limit.
        """
        arr = _poses_array(poses)
        out: List[bool] = []
        batch: List[Any] = []
        size = 0

        def flush() -> None:
            if batch:
                doc = self._json(
                    "POST",
                    f"/v1/episodes/{self._seg(episode_id)}/feasible",
                    body={"poses": batch},
                )
                got = doc["feasible"]
                if len(got) != len(batch):
                    raise TransportError(
                        f"feasible: sent {len(batch)} poses, got {len(got)} answers"
                    )
                out.extend(bool(x) for x in got)

        for p in arr:
            pj = pose_to_json(p)
            n = len(json.dumps(pj)) + 2
            if batch and (len(batch) >= MAX_FEASIBLE_BATCH or size + n > MAX_FEASIBLE_BYTES):
                flush()
                batch, size = [], 0
            batch.append(pj)
            size += n
        flush()
        return np.asarray(out, dtype=bool)

    def act(self, episode_id: str, step: int, action: Dict[str, Any]) -> Dict[str, Any]:
        """``POST /v1/episodes/{id}/actions`` with ``{"step": step, "action": action}``.

        Returns the response (``{"accepted": true, "observation": OBS}``).  Low level: prefer
        :meth:`Episode.move` and :meth:`Episode.stop`, which keep the step index.
        """
        return cast(Dict[str, Any], self._json(
            "POST",
            f"/v1/episodes/{self._seg(episode_id)}/actions",
            body={"step": step, "action": action},
        ))

    def result(self, episode_id: str) -> Result:
        """``GET /v1/episodes/{id}/result`` (409 :class:`objview.EpisodeRunning` while running)."""
        return cast(Result, self._json("GET", f"/v1/episodes/{self._seg(episode_id)}/result"))


class Response:
    """A successful HTTP answer: ``status``, ``headers`` (as received) and ``content`` (the
    body, gzip-decoded)."""

    def __init__(self, status: int, headers: Dict[str, str], content: bytes):
        self.status = status
        self.headers = headers
        self.content = content

    def header(self, name: str) -> Optional[str]:
        low = name.lower()
        for k, v in self.headers.items():
            if k.lower() == low:
                return v
        return None


class Observation:
    """One view of an episode.

    ``step`` (0 = start view), ``pose`` (float64 array (7,)), ``done``, ``terminal`` (None while
    running, else ``{"source", "reason", "detail"}``), ``depth`` (float32 array (512, 512),
    camera-frame z, 0 = no hit; fetched from the server on first access unless it was prefetched)
    and :meth:`rgb` (uint8 array (H, W, 3), fetched on demand).  Camera: ``intrinsics``,
    :attr:`K` (3×3), :attr:`cam_to_world` (4×4, OpenCV axes) and :meth:`points` (the observed
    points in the object frame).

    A view's images can be fetched while it is the episode's current view (and after the end,
    for the last view); reading ``depth`` of an older observation after a later action raises
    :class:`objview.StaleStep`.
    """

    def __init__(self, episode: "Episode", meta: ObservationMeta):
        self.episode = episode
        self.step = int(meta["step"])
        pose = meta.get("pose")
        self.pose = np.asarray(pose if pose is not None else [np.nan] * 7, dtype=np.float64)
        self.done = bool(meta.get("done", False))
        self.terminal: Optional[Terminal] = meta.get("terminal")
        # Camera intrinsics of the view (width, height, fx, fy, cx, cy, znear, zfar).
        self.intrinsics: Intrinsics = meta.get("intrinsics") or episode.intrinsics
        self.meta = meta
        self._depth: Optional[np.ndarray] = None
        self._rgb: Optional[np.ndarray] = None

    def __repr__(self) -> str:
        t = f", terminal={self.terminal}" if self.terminal else ""
        return f"Observation(step={self.step}, pose={self.pose.tolist()}, done={self.done}{t})"

    @property
    def depth(self) -> np.ndarray:
        if self._depth is None:
            ep = self.episode
            self._depth = ep.client.depth(ep.id, step=None if self.done else self.step)
        return self._depth

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the usual name of the matrix
        """The 3×3 intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (float64)."""
        return camera.intrinsics_matrix(self.intrinsics)

    @property
    def cam_to_world(self) -> np.ndarray:
        """The 4×4 camera-to-object transform of this view (float64; OpenCV camera: x right,
        y down, z forward; columns right, down, forward, centre).  See :mod:`objview.camera`."""
        return camera.cam_to_world(self.pose)

    def points(self, stride: int = 1) -> np.ndarray:
        """The observed points of this view: float64 (M, 3), object frame — every pixel with a
        hit (``u``, ``v`` multiples of ``stride``) back-projected through its centre at its depth,
        row-major.  With ``stride=1``, bit for bit the renderer's cloud (``objview render
        --points`` writes it as float32).  Reads :attr:`depth` (a request unless fetched)."""
        return camera.backproject(self.depth, self.pose, self.intrinsics, stride=stride)

    def rgb(self) -> np.ndarray:
        """The RGB image of this view (uint8, (H, W, 3)); decoded with Pillow if installed."""
        if self._rgb is None:
            ep = self.episode
            png = ep.client.rgb_png(ep.id, step=None if self.done else self.step)
            self._rgb = decode_png(png)
        return self._rgb

    def rgb_png(self) -> bytes:
        """The PNG bytes of this view's RGB image."""
        ep = self.episode
        return ep.client.rgb_png(ep.id, step=None if self.done else self.step)


class Episode:
    """A running (or finished) episode on the server.

    Attributes from the create response: ``id``, ``object_id``, ``split``, ``view_space``,
    ``budget`` (``"auto"`` or the integer K), ``seed`` (the per-episode seed, as a local
    ``objview run`` hands its planners), ``candidate_set``, ``start_pose``, ``intrinsics``,
    ``action_timeout_s``.  ``candidates`` is the candidate set as a float64 array (N, 7).

    A context manager: ``with client.create_episode(...) as ep:`` aborts the episode (as a
    planner error, :meth:`abort`) when the block ends before the episode did — an exception,
    ``KeyboardInterrupt``, or a ``break`` — so nothing is left running on the server.
    """

    def __init__(
        self,
        client: Client,
        doc: Dict[str, Any],
        method: Optional[str] = None,
        eager_depth: bool = True,
    ):
        self.client = client
        self.doc = doc
        self.id: str = doc["episode_id"]
        self.object_id: Optional[str] = doc.get("object_id")
        self.split: Optional[str] = doc.get("split")
        self.view_space: Optional[str] = doc.get("view_space")
        b = doc.get("budget", "auto")
        self.budget: Union[int, str] = int(b) if isinstance(b, int) or str(b).isdigit() else b
        self.seed: Optional[int] = doc.get("seed")
        self.candidate_set: Optional[str] = doc.get("candidate_set")
        sp = doc.get("start_pose")
        if sp is None and doc.get("history"):
            sp = doc["history"][0]
        self.start_pose = None if sp is None else np.asarray(sp, dtype=np.float64)
        self.intrinsics: Intrinsics = doc.get("intrinsics") or cast(Intrinsics, {})
        self.action_timeout_s: Optional[float] = doc.get("action_timeout_s")
        self.method = method if method is not None else doc.get("method")
        self.eager_depth = eager_depth
        self._result: Optional[Result] = None
        self._obs = self._observation_from(doc["observation"])

    def __repr__(self) -> str:
        return (
            f"Episode(id={self.id!r}, object_id={self.object_id!r}, step={self.step}, "
            f"done={self.done})"
        )

    def __enter__(self) -> "Episode":
        return self

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> None:
        if self.done:
            return
        if exc_type is None:
            detail = "the client's `with` block ended before the episode did"
        else:
            detail = f"{exc_type.__name__}: {exc}"
        self._abort_quietly(detail)

    def _abort_quietly(self, detail: str) -> None:
        """:meth:`abort`, logging (not raising) a failure: used while another exception is on
        its way, which must not be replaced."""
        try:
            self.abort(detail)
        except Exception as e:  # noqa: BLE001 - never mask the exception being handled
            logger.warning("could not abort episode %s: %s", self.id, e)
        else:
            logger.info("aborted episode %s: %s", self.id, detail)

    # --------------------------------------------------------------------------- state
    @property
    def step(self) -> int:
        """The current observation's step (the one the next action must carry)."""
        return self._obs.step

    @property
    def done(self) -> bool:
        return self._obs.done

    @property
    def terminal(self) -> Optional[Terminal]:
        """None while running; then ``{"source", "reason", "detail"}``."""
        return self._obs.terminal

    @property
    def fixed_budget(self) -> Optional[int]:
        """K when the budget is a number, None for ``"auto"``."""
        return self.budget if isinstance(self.budget, int) else None

    @property
    def candidates(self) -> np.ndarray:
        """The episode's candidate set (float64 (N, 7), read-only; cached by the client)."""
        if self.candidate_set is None:
            raise ValueError("the server did not name this episode's candidate set")
        return self.client.candidate_set(self.candidate_set)

    def _observation_from(self, meta: ObservationMeta) -> Observation:
        obs = Observation(self, meta)
        if self.eager_depth and not obs.done:
            obs.depth  # noqa: B018 - prefetch while this view is current
        return obs

    def observation(self) -> Observation:
        """The current observation (no request unless its depth was not fetched yet)."""
        return self._obs

    def refresh(self) -> Observation:
        """Re-read the current observation from the server (e.g. after a timeout)."""
        try:
            meta = cast(ObservationMeta, self.client.observation_meta(self.id))
        except ServerError as e:
            if e.code != "episode_finished":
                raise
            st = self.status()
            meta = {
                "step": st.get("step", self.step),
                "pose": (st.get("history") or [self._obs.pose.tolist()])[-1],
                "done": True,
                "terminal": st.get("terminal"),
            }
        if meta.get("step") != self._obs.step or bool(meta.get("done")) != self._obs.done:
            self._obs = self._observation_from(meta)
        else:
            self._obs.done = bool(meta.get("done"))
            self._obs.terminal = meta.get("terminal")
        return self._obs

    def status(self) -> Dict[str, Any]:
        """``GET /v1/episodes/{id}``: state, step, views, history, terminal (+ metrics on
        public splits)."""
        return self.client.episode_status(self.id)

    # -------------------------------------------------------------------------- actions
    def feasible(self, poses: Any) -> np.ndarray:
        """Feasibility of poses in this episode's view space: bool array (M,)."""
        return self.client.feasible(self.id, poses)

    def act(self, action: Dict[str, Any], step: Optional[int] = None) -> Observation:
        """Send an ACTION object (``{"type": "move", "pose": …}`` or ``{"type": "stop",
        "reason": …}``) for ``step`` (default: the current step) and return the new
        observation.  A stale step raises :class:`objview.StaleStep` and changes nothing.

        Low level: the action is sent as it is (a malformed one ends the episode with
        ``invalid_action``, the benchmark's rule); :meth:`move` and :meth:`stop` check theirs."""
        resp = self.client.act(self.id, self.step if step is None else int(step), action)
        self._obs = self._observation_from(resp["observation"])
        return self._obs

    def move(self, pose: PoseLike, step: Optional[int] = None) -> Observation:
        """Move the camera to ``pose`` (7 numbers); returns the new observation (``done`` and
        ``terminal`` set when this move ended the episode)."""
        return self.act({"type": "move", "pose": pose_to_json(pose)}, step=step)

    def stop(self, reason: str = "plan_end", step: Optional[int] = None) -> Observation:
        """End the episode with a stop ``reason`` (one of :data:`STOP_REASONS`; anything else
        raises :class:`ValueError` and sends nothing)."""
        return self.act({"type": "stop", "reason": check_stop_reason(reason)}, step=step)

    def abort(self, detail: Optional[str] = None) -> Observation:
        """End the episode as a failure of the planner (``POST …/abort``): source
        ``exception``, reason ``planner_error``, ``detail`` recorded, the views taken scored —
        what a local ``objview run`` records when a planner raises.  Use it when your planner
        gives up on an episode, so that the server does not wait for the action timeout.

        Returns the last observation (``done``).  An episode that has already ended is left as
        it is (its final observation is returned)."""
        if self.done:
            return self._obs
        try:
            resp = self.client.abort(self.id, detail)
        except EpisodeFinished:
            return self.refresh()
        self._obs = Observation(self, resp["observation"])
        return self._obs

    # --------------------------------------------------------------------------- result
    def result(self) -> Result:
        """The finished episode's result: one ``objview run`` JSON line as a dict (cached)."""
        if self._result is None:
            self._result = self.client.result(self.id)
        return self._result

    def history(self) -> List[List[float]]:
        """The poses taken so far (start view first), from the server."""
        return cast(List[List[float]], self.status().get("history", []))


def iter_objects(client: Client, split: str, objects: Optional[Iterable[Any]] = None) -> List[Any]:
    """The object references of a split to run: ``objects`` as given, else every index."""
    if objects is not None:
        return list(objects)
    return list(range(int(client.split(split)["objects"])))
