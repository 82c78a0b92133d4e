"""The planner loop: run a Python planner over a split of the server, one episode per object.

A planner is any object with two methods (subclassing :class:`Planner` is optional):

- ``reset(episode)``: a new episode starts (``episode.seed``, ``episode.candidates``,
  ``episode.intrinsics``, ``episode.feasible(poses)``, ``episode.fixed_budget`` …);
- ``act(observation, episode)`` → ``("move", pose)`` or ``("stop", reason)`` (a dict ACTION
  of the HTTP contract, ``{"type": "move", "pose": …}``, is accepted too).

The server ends the episode (budget checkpoints, cap, ``enough_info``, an invalid action, a
timeout); the loop stops when it does and collects the result.  If anything goes wrong on the
client's side — the planner raises, an invalid stop reason, ``KeyboardInterrupt`` — the loop
aborts the episode on the server (source ``exception``, reason ``planner_error``, the views
scored) and re-raises, so no episode is left running.

Progress lines go to the ``objview.planner`` logger (INFO), never to stdout/stderr directly.
"""

from __future__ import annotations

import concurrent.futures
import copy
import logging
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

from .client import (
    Client,
    Episode,
    Observation,
    check_stop_reason,
    iter_objects,
    pose_to_json,
)
from .errors import TooManyEpisodes
from .types import Result

__all__ = ["Planner", "action_to_json", "run_episode", "run_planner", "summary_line"]

logger = logging.getLogger(__name__)

Action = Union[Tuple[str, Any], Dict[str, Any]]
Progress = Union[bool, None, Callable[[int, Result], None]]


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


class Cancelled(Exception):
    """Raised inside the episodes of :func:`run_planner` still running when another one failed
    (or the run was interrupted): they are aborted, the first failure is re-raised."""


def action_to_json(action: Action) -> Dict[str, Any]:
    """A planner's action as the contract's ACTION object.  A stop with a reason that is not
    one of :data:`objview.STOP_REASONS` raises :class:`ValueError` (it would otherwise end the
    episode as ``invalid_action``)."""
    if isinstance(action, dict):
        if action.get("type") == "stop":
            check_stop_reason(action.get("reason"))
        return action
    if isinstance(action, (tuple, list)) and len(action) == 2:
        kind, arg = action
        if kind == "move":
            return {"type": "move", "pose": pose_to_json(arg)}
        if kind == "stop":
            return {"type": "stop", "reason": check_stop_reason(arg)}
    raise ValueError(f"a planner action is ('move', pose) or ('stop', reason), not {action!r}")


def run_episode(
    planner: Any, episode: Episode, cancel: Optional[threading.Event] = None
) -> Result:
    """Drive one created episode with ``planner`` until the server ends it; return the result.

    Any exception (``KeyboardInterrupt`` included) aborts the episode on the server, then
    propagates.  ``cancel``: an event checked before each action (set → :class:`Cancelled`).
    """
    with episode:  # aborts the episode if the block ends before it does
        planner.reset(episode)
        obs = episode.observation()
        while not obs.done:
            action = action_to_json(planner.act(obs, episode))
            if cancel is not None and cancel.is_set():
                raise Cancelled("another episode of this run failed")
            obs = episode.act(action)
        return episode.result()


#: How long :func:`run_planner` keeps asking for a place on a full server (seconds).
CREATE_WAIT_MAX_S = 600.0
#: The first wait before asking again; it doubles up to :data:`CREATE_RETRY_MAX_S`.
CREATE_RETRY_FIRST_S = 0.25
CREATE_RETRY_MAX_S = 4.0


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
    progress: Progress = False,
    workers: int = 1,
) -> List[Result]:
    """Run ``planner`` on every object of ``split`` (or the given indices/uids), one episode
    each; return the result dicts in object order.

    ``method`` defaults to the planner's ``name`` attribute or its class name; ``family`` and
    ``execution_mode`` to the planner's attributes of those names (else ``classical`` /
    ``iterative``).  ``eager_depth=False`` skips downloading depth images the planner never
    reads (it is still fetched on access of ``observation.depth``).  ``progress``: True logs
    one line per episode (:func:`summary_line`) at INFO level on the ``objview.planner`` logger;
    a callable gets ``(index, result)`` (called from one thread at a time).

    ``workers=N`` (N > 1) runs up to N episodes at once, each worker thread with its own
    ``copy.deepcopy`` of ``planner`` (so a planner keeps per-episode state in ``self`` safely;
    the client is shared — it is thread-safe).  The results are the same as a sequential run's:
    each episode depends on its own seed only (record_timings aside).

    A full server (``TooManyEpisodes``: its cap on running episodes, in all or of this token,
    is reached — more ``workers`` than it allows) is waited for: the create is asked again after
    0.25 s, doubling to 4 s, for up to :data:`CREATE_WAIT_MAX_S` seconds, as ``objview run
    --server`` does.

    An exception — in the planner, a protocol error, ``KeyboardInterrupt`` — aborts the episode
    it happened in (source ``exception``, reason ``planner_error``, its views scored) and any
    other episode of the run still going, then propagates; no episode is left running.
    """
    if method is None:
        method = getattr(planner, "name", None) or type(planner).__name__
    if family is None:
        family = getattr(planner, "family", "classical")
    if execution_mode is None:
        execution_mode = getattr(planner, "execution_mode", "iterative")
    objs = iter_objects(client, split, objects)
    lock = threading.Lock()

    def create(obj: Any, cancel: Optional[threading.Event]) -> Episode:
        started, wait = time.monotonic(), CREATE_RETRY_FIRST_S
        while True:
            try:
                return client.create_episode(
                    split,
                    obj,
                    view_space=view_space,
                    budget=budget,
                    method=str(method),
                    family=str(family),
                    execution_mode=str(execution_mode),
                    candidate_set=candidate_set,
                    seed=seed,
                    params=params,
                    record_timings=record_timings,
                    eager_depth=eager_depth,
                )
            except TooManyEpisodes:
                if time.monotonic() - started + wait > CREATE_WAIT_MAX_S:
                    raise
            if cancel is None:
                time.sleep(wait)
            elif cancel.wait(wait):
                raise Cancelled("another episode of this run failed")
            wait = min(2 * wait, CREATE_RETRY_MAX_S)

    def one(p: Any, i: int, obj: Any, cancel: Optional[threading.Event]) -> Result:
        ep = create(obj, cancel)
        res = run_episode(p, ep, cancel)
        with lock:
            if callable(progress):
                progress(i, res)
            elif progress:
                logger.info("%s", summary_line(res))
        return res

    if workers <= 1 or len(objs) <= 1:
        return [one(planner, i, obj, None) for i, obj in enumerate(objs)]

    cancel = threading.Event()
    local = threading.local()

    def job(i: int, obj: Any) -> Result:
        if cancel.is_set():
            raise Cancelled("another episode of this run failed")
        p = getattr(local, "planner", None)
        if p is None:
            p = local.planner = copy.deepcopy(planner)
        return one(p, i, obj, cancel)

    pool = concurrent.futures.ThreadPoolExecutor(
        max_workers=min(int(workers), len(objs)), thread_name_prefix="objview-run"
    )
    futures = [pool.submit(job, i, obj) for i, obj in enumerate(objs)]
    try:
        for f in concurrent.futures.as_completed(futures):
            f.result()  # the first failure stops the run
    except BaseException:
        cancel.set()
        for f in futures:
            f.cancel()
        concurrent.futures.wait(futures)  # the running ones abort their episodes
        raise
    finally:
        pool.shutdown(wait=True)
    return [f.result() for f in futures]


def _fmt(x: Any) -> str:
    return "-" if x is None else f"{x:.3f}"


def _checkpoint_text(cp: Dict[str, Any]) -> str:
    sc = (cp.get("sc") or {}).get("0.02")
    nsc = (cp.get("nsc") or {}).get("0.02")
    return (
        f"{cp.get('views')} views, NSC@0.02 {_fmt(nsc)}, SC@0.02 {_fmt(sc)}, "
        f"path {_fmt(cp.get('path_cost'))}"
    )


def summary_line(res: Result) -> str:
    """One line about a result: uid, the terminal checkpoint (views, NSC/SC@0.02, path), the
    terminal reason, and — for ``auto`` budgets — the automatic result, the ``MS@0.02``
    checkpoint (where the benchmark reads an ``auto`` run; the run itself goes on to
    ``enough_info`` or the cap)."""
    cps: Dict[str, Any] = dict(res.get("checkpoints") or {})
    line = (
        f"{res.get('uid')}: {_checkpoint_text(cps.get('terminal') or {})}, "
        f"{res.get('terminal_reason')} ({res.get('terminal_source')})"
    )
    if str(res.get("budget")) == "auto":
        ms = cps.get("MS@0.02")
        line += f"; auto (MS@0.02): {_checkpoint_text(ms) if ms else 'not reached'}"
    return line
