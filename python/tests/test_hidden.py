"""Hidden means hidden: no metric, geometry or path in any response about a running episode."""

from __future__ import annotations

import json

import numpy as np
import pytest

import objview

# Keys that carry metrics or ground truth in results (checkpoints, steps, reference…).
METRIC_KEYS = {
    "sc", "nsc", "cd", "metrics", "checkpoints", "steps", "coverage", "reference",
    "gt_points", "gt_source", "gt_cloud", "mesh", "surface_voxels", "observable", "ms",
}


class RecordingClient(objview.Client):
    """A client that keeps every JSON response it receives."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.seen = []

    def request(self, method, path, body=None, query=None, raw_body=None):
        resp = super().request(method, path, body=body, query=query, raw_body=raw_body)
        ctype = (resp.header("Content-Type") or "").lower()
        if "json" in ctype and "ndjson" not in ctype:
            self.seen.append((method, path, json.loads(resp.content)))
        return resp


def keys(doc, out=None):
    out = set() if out is None else out
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.add(k.lower())
            keys(v, out)
    elif isinstance(doc, list):
        for v in doc:
            keys(v, out)
    return out


def test_no_metric_reaches_a_planner_before_the_end(server, pool):
    from conftest import TOKEN

    client = RecordingClient(server.url, token=TOKEN)
    client.splits()
    client.split("tiny")
    ep = client.create_episode("tiny", 1, view_space="quarter", budget=5, method="t-hidden")
    c = ep.candidates
    ok = np.flatnonzero(ep.feasible(c))
    ep.status()
    client.observation_meta(ep.id)
    for i in ok[:5]:
        ep.move(c[i])
        ep.status()
        client.observation_meta(ep.id)
    assert not ep.done
    ep.stop("plan_end")
    running = [r for r in client.seen if not r[1].endswith("/result")]
    assert len(running) >= 15
    for method, path, doc in running:
        leaked = keys(doc) & METRIC_KEYS
        assert not leaked, f"{method} {path} carries {leaked}: {doc}"
        text = json.dumps(doc)
        # Object ids are opaque uids, never paths of the pool.
        assert str(pool.root) not in text and ".obj" not in text and ".pcd" not in text, text
    # The metrics are in the result, after the end.
    res = ep.result()
    assert res["checkpoints"]["terminal"]["views"] == 6
    assert "0.02" in res["checkpoints"]["K=5"]["sc"]


def test_public_splits_show_metrics_while_running(client):
    ep = client.create_episode("tiny-public", 0, budget=5, method="t-public")
    ep.move(ep.candidates[3])
    st = ep.status()
    assert st["state"] == "running"
    assert "metrics" in st and st["metrics"], st
    ep.stop("plan_end")


def test_hidden_split_status_has_no_metrics(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-hidden")
    ep.move(ep.candidates[3])
    st = ep.status()
    assert "metrics" not in st
    ep.stop("plan_end")
    with pytest.raises(objview.EpisodeFinished):
        ep.move(ep.candidates[4])
