"""Tests that need no server: error mapping, pose serialization, the PNG decoder, actions."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest

import objview
from objview._png import decode_png_builtin
from objview.errors import error_from_response
from objview.planner import action_to_json


@pytest.mark.parametrize(
    "status,code,cls",
    [
        (400, "malformed_json", objview.MalformedJSON),
        (401, "unauthorized", objview.Unauthorized),
        (404, "not_found", objview.NotFound),
        (405, "method_not_allowed", objview.MethodNotAllowed),
        (409, "stale_step", objview.StaleStep),
        (409, "episode_finished", objview.EpisodeFinished),
        (409, "episode_running", objview.EpisodeRunning),
        (413, "payload_too_large", objview.PayloadTooLarge),
        (422, "invalid_request", objview.InvalidRequest),
        (408, "request_timeout", objview.RequestTimeout),
        (429, "too_many_episodes", objview.TooManyEpisodes),
        (503, "overloaded", objview.Overloaded),
    ],
)
def test_error_codes_map_to_classes(status, code, cls):
    body = json.dumps({"error": {"code": code, "message": "field `x`"}}).encode()
    e = error_from_response(status, body)
    assert type(e) is cls
    assert isinstance(e, objview.ServerError) and isinstance(e, objview.ObjViewError)
    assert (e.status, e.code, e.message) == (status, code, "field `x`")


def test_unknown_error_bodies_fall_back_on_the_status():
    e = error_from_response(404, b"not json")
    assert type(e) is objview.NotFound and e.code == "http_404" and e.message == "not json"
    e = error_from_response(409, json.dumps({"error": {"code": "new_code", "message": "m"}}).encode())
    assert type(e) is objview.ServerError and e.code == "new_code" and e.status == 409
    e = error_from_response(500, b"")
    assert type(e) is objview.ServerError and e.status == 500


def test_pose_to_json_keeps_float64_and_maps_non_finite_to_null():
    p = np.array([1 / 3, 2.0, -3.0, 0, 0, 0, 0.1], dtype=np.float64)
    out = objview.pose_to_json(p)
    assert out == p.tolist() and all(type(x) is float for x in out)
    assert json.loads(json.dumps(out)) == p.tolist()  # exact round trip
    assert objview.pose_to_json([1, np.nan, np.inf, 0, 0, 0, 0]) == [1.0, None, None, 0, 0, 0, 0]
    assert objview.pose_to_json("garbage") == "garbage"


def test_planner_actions_become_contract_actions():
    assert action_to_json(("stop", "plan_end")) == {"type": "stop", "reason": "plan_end"}
    assert action_to_json(("move", np.zeros(7))) == {"type": "move", "pose": [0.0] * 7}
    raw = {"type": "move", "pose": [1] * 7}
    assert action_to_json(raw) is raw
    with pytest.raises(ValueError):
        action_to_json("left")


def _png(img: np.ndarray, filters) -> bytes:
    """Encode an RGB8 image with the given row filters (one per row, cycling)."""
    h, w, c = img.shape
    stride = w * c
    rows = img.reshape(h, stride).astype(np.int32)
    raw = bytearray()
    prev = np.zeros(stride, dtype=np.int32)
    for y in range(h):
        f = filters[y % len(filters)]
        cur = rows[y]
        left = np.concatenate([np.zeros(c, dtype=np.int32), cur[:-c]])
        upleft = np.concatenate([np.zeros(c, dtype=np.int32), prev[:-c]])
        if f == 0:
            enc = cur
        elif f == 1:
            enc = cur - left
        elif f == 2:
            enc = cur - prev
        elif f == 3:
            enc = cur - (left + prev) // 2
        else:
            pa, pb, pc = np.abs(prev - upleft), np.abs(left - upleft), np.abs(left + prev - 2 * upleft)
            pred = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, upleft))
            enc = cur - pred
        raw.append(f)
        raw.extend((enc & 0xFF).astype(np.uint8).tobytes())
        prev = cur

    def chunk(kind, data):
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(bytes(raw)))
        + chunk(b"IEND", b"")
    )


def test_builtin_png_decoder_reverses_every_filter():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, size=(9, 11, 3), dtype=np.uint8)
    data = _png(img, [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(decode_png_builtin(data), img)
    with pytest.raises(ValueError):
        decode_png_builtin(b"not a png")
