"""Exceptions of the objview client.

Every error response of the server is ``{"error": {"code": "...", "message": "..."}}`` with an
HTTP status (docs/server-api.md).  :func:`error_from_response` turns it into the subclass of
:class:`ServerError` registered for its ``code`` (falling back on the HTTP status), so callers can
write ``except objview.StaleStep:``.
"""

from __future__ import annotations

import json
from typing import Any, Dict, Optional, Type


class ObjViewError(Exception):
    """Base class of every exception raised by this package."""


class TransportError(ObjViewError):
    """The server could not be reached, or its answer was not what the contract says."""


class ServerError(ObjViewError):
    """An error response of the server.

    Attributes: ``status`` (HTTP status), ``code`` (the contract's error code, e.g.
    ``"stale_step"``), ``message`` (the server's text) and ``body`` (the decoded JSON body, or
    the raw text when it was not JSON).
    """

    #: The contract's error code of this class (None for the base class).
    CODE: Optional[str] = None
    #: The HTTP status this class stands for when the server sends no known code.
    STATUS: Optional[int] = None

    def __init__(self, status: int, code: str, message: str, body: Any = None):
        self.status = status
        self.code = code
        self.message = message
        self.body = body
        super().__init__(f"HTTP {status} {code}: {message}")


class MalformedJSON(ServerError):
    """400 ``malformed_json``: the request body is not JSON."""

    CODE, STATUS = "malformed_json", 400


class Unauthorized(ServerError):
    """401 ``unauthorized``: token missing or unknown."""

    CODE, STATUS = "unauthorized", 401


class NotFound(ServerError):
    """404 ``not_found``: unknown episode, split, object, method or route."""

    CODE, STATUS = "not_found", 404


class MethodNotAllowed(ServerError):
    """405 ``method_not_allowed``."""

    CODE, STATUS = "method_not_allowed", 405


class StaleStep(ServerError):
    """409 ``stale_step``: the action's step is not the current one; the episode goes on."""

    CODE, STATUS = "stale_step", None


class EpisodeFinished(ServerError):
    """409 ``episode_finished``: an action or observation request after the episode ended."""

    CODE, STATUS = "episode_finished", None


class EpisodeRunning(ServerError):
    """409 ``episode_running``: the result was requested before the episode ended."""

    CODE, STATUS = "episode_running", None


class PayloadTooLarge(ServerError):
    """413 ``payload_too_large``: request body over the server's limit (1 MiB)."""

    CODE, STATUS = "payload_too_large", 413


class InvalidRequest(ServerError):
    """422 ``invalid_request``: JSON of the wrong shape or type, unknown split/space/budget."""

    CODE, STATUS = "invalid_request", 422


class RequestTimeout(ServerError):
    """408 ``request_timeout``: the request body did not arrive within the server's limit."""

    CODE, STATUS = "request_timeout", 408


class TooManyEpisodes(ServerError):
    """429 ``too_many_episodes``: the server's cap on running episodes (in all, or of this
    token) is reached; finish or abort an episode, or wait for idle ones to time out."""

    CODE, STATUS = "too_many_episodes", 429


class Overloaded(ServerError):
    """503 ``overloaded``: every connection the server keeps open is busy; retry later."""

    CODE, STATUS = "overloaded", 503


_BY_CODE: Dict[str, Type[ServerError]] = {}
_BY_STATUS: Dict[int, Type[ServerError]] = {}
for _cls in (
    MalformedJSON,
    Unauthorized,
    NotFound,
    MethodNotAllowed,
    StaleStep,
    EpisodeFinished,
    EpisodeRunning,
    PayloadTooLarge,
    InvalidRequest,
    RequestTimeout,
    TooManyEpisodes,
    Overloaded,
):
    _BY_CODE[str(_cls.CODE)] = _cls
    if _cls.STATUS is not None:
        _BY_STATUS[_cls.STATUS] = _cls


def error_from_response(status: int, raw: bytes) -> ServerError:
    """The exception for an error response (``status`` >= 400, body ``raw``)."""
    text = raw.decode("utf-8", errors="replace")
    body: Any = text
    code = ""
    message = text.strip() or f"HTTP {status}"
    try:
        body = json.loads(text)
    except ValueError:
        pass
    else:
        err = body.get("error") if isinstance(body, dict) else None
        if isinstance(err, dict):
            code = str(err.get("code", ""))
            message = str(err.get("message", message))
    cls = _BY_CODE.get(code) or _BY_STATUS.get(status) or ServerError
    return cls(status, code or f"http_{status}", message, body)
