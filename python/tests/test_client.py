"""The client against a real server: catalogue routes, episodes, depth, RGB, feasibility."""

from __future__ import annotations

import numpy as np
import pytest

import objview
from conftest import OTHER_TOKEN, START, run_bin


def test_health_needs_no_token_and_the_rest_does(server):
    anon = server.client(token=None)
    assert anon.health()["status"] == "ok"
    with pytest.raises(objview.Unauthorized) as e:
        anon.splits()
    assert e.value.status == 401 and e.value.code == "unauthorized"
    with pytest.raises(objview.Unauthorized):
        server.client(token="nope").splits()


def test_catalogue(client):
    splits = {s["id"]: s for s in client.splits()}
    assert splits["tiny"] == {"id": "tiny", "objects": 2, "public": False}
    assert splits["tiny-public"]["public"] is True
    tiny = client.split("tiny")
    assert tiny["object_ids"] == ["cube", "cone"]  # the split file's order
    assert tiny["objects"] == 2 and tiny["public"] is False
    assert client.view_spaces() == ["whole", "hemi", "quarter", "eighth"]
    assert set(client.candidate_sets()) >= {"tammes-128", "tammes-360"}
    for name, n in [("tammes-128", 128), ("tammes-360", 360)]:
        c = client.candidate_set(name)
        assert c.shape == (n, 7) and c.dtype == np.float64
        np.testing.assert_allclose(np.linalg.norm(c[:, :3], axis=1), 3.0, atol=1e-9)
        assert np.all(c[:, 3:] == 0.0)
    doc = client.openapi()
    assert str(doc.get("openapi", "")).startswith("3.")
    for route in ["/v1/episodes", "/v1/splits", "/v1/episodes/{id}/actions"]:
        assert route in doc["paths"], route


def test_not_found_and_method_not_allowed(client):
    with pytest.raises(objview.NotFound):
        client.split("no-such-split")
    with pytest.raises(objview.NotFound):
        client.candidate_set("tammes-7")
    with pytest.raises(objview.NotFound):
        client.episode_status("e-does-not-exist")
    with pytest.raises(objview.NotFound):
        client.request("GET", "/v1/no-such-route")
    with pytest.raises(objview.MethodNotAllowed) as e:
        client.request("POST", "/v1/splits", body={})
    assert e.value.status == 405


def test_create_request_validation(client):
    with pytest.raises(objview.InvalidRequest):
        client.create_episode("tiny", 0, view_space="nowhere")
    with pytest.raises(objview.InvalidRequest):
        client.create_episode("tiny", 0, budget=0)
    with pytest.raises(objview.InvalidRequest):
        client.create_episode("tiny", 0, family="oracle")
    with pytest.raises(objview.InvalidRequest):
        client.create_episode("tiny", 0, candidate_set="tammes-7")
    with pytest.raises(objview.NotFound):
        client.create_episode("tiny", 99)
    with pytest.raises(objview.NotFound):
        client.create_episode("tiny", "no-such-uid")
    # The contract lists an unknown split under both 404 and 422; either is an error.
    with pytest.raises((objview.NotFound, objview.InvalidRequest)):
        client.create_episode("no-such-split", 0)
    with pytest.raises(objview.MalformedJSON) as e:
        client.request("POST", "/v1/episodes", raw_body=b"{not json")
    assert e.value.status == 400


def test_episode_start_view_depth_and_rgb(server, client, pool, objview_bin, tmp_path):
    ep = client.create_episode("tiny", "cube", budget=5, method="t-basics", seed=3)
    assert ep.object_id == "cube" and ep.split == "tiny" and ep.view_space == "whole"
    assert ep.budget == 5 and ep.fixed_budget == 5 and ep.candidate_set == "tammes-360"
    assert isinstance(ep.seed, int)
    np.testing.assert_allclose(ep.start_pose, [START] * 3 + [0.0] * 4, atol=1e-12)
    k = ep.intrinsics
    assert (k["width"], k["height"]) == (512, 512)
    assert k["fx"] == pytest.approx(256 / np.tan(np.radians(22.5)), rel=1e-9)
    assert (k["cx"], k["cy"], k["znear"], k["zfar"]) == (256.0, 256.0, 0.01, 10.0)
    assert ep.candidates.shape == (360, 7)

    obs = ep.observation()
    assert obs.step == 0 and not obs.done and obs.terminal is None and ep.step == 0
    assert obs.meta["intrinsics"] == k and obs.intrinsics == k  # every observation carries them
    d = obs.depth
    assert d.shape == (512, 512) and d.dtype == np.float32
    # The unit cube's corner faces the start view: the centre ray hits it at depth ≈ 3 − 1.
    assert 0.0 < d[256, 256] < 3.0
    assert abs(float(d[256, 256]) - 2.0) < 0.01, d[256, 256]
    assert (d == 0).any() and (d > 0).mean() > 0.2  # background and object

    # The same depth as a local render of the same mesh from the same pose, bit for bit.
    out = tmp_path / "start.npy"
    mesh = pool.root / pool.entries["cube"]["mesh"]
    pose = ",".join(repr(float(x)) for x in ep.start_pose)
    run_bin(objview_bin, "render", str(mesh), "--normalize", "none", "--pose", pose,
            "--depth", str(out))
    np.testing.assert_array_equal(d, np.load(out))

    # The depth of a given step; a step that is not current is stale.
    np.testing.assert_array_equal(client.depth(ep.id, step=0), d)
    with pytest.raises(objview.StaleStep):
        client.depth(ep.id, step=1)

    rgb = obs.rgb()
    assert rgb.shape == (512, 512, 3) and rgb.dtype == np.uint8
    assert rgb.reshape(-1, 3).std(axis=0).max() > 0  # not a blank image

    st = ep.status()
    assert st["state"] == "running" and st["step"] == 0 and st["views"] == 1
    assert st["episode_id"] == ep.id and st["method"] == "t-basics"
    np.testing.assert_allclose(st["history"], [ep.start_pose])

    # Moves: step and pose advance, depth changes.
    c = ep.candidates
    o1 = ep.move(c[0])
    assert o1.step == 1 and ep.step == 1 and not o1.done
    np.testing.assert_array_equal(o1.pose, c[0])
    assert not np.array_equal(o1.depth, d)
    with pytest.raises(objview.EpisodeRunning) as e:
        ep.result()
    assert e.value.status == 409
    o2 = ep.stop("plan_end")
    assert o2.done and ep.done
    assert ep.terminal["source"] == "algorithm_stop" and ep.terminal["reason"] == "plan_end"
    res = ep.result()
    assert res["uid"] == "cube" and res["method"] == "t-basics"
    assert res["terminal_reason"] == "plan_end" and len(res["visited_poses"]) == 2
    # The last view's images stay available after the end.
    assert client.depth(ep.id).shape == (512, 512)
    assert ep.status()["state"] == "finished"


def test_feasibility_batch(client):
    ep = client.create_episode("tiny", 0, view_space="hemi", budget=5, method="t-feasible")
    c = ep.candidates
    f = ep.feasible(c)
    assert f.dtype == bool and f.shape == (360,)
    z = c[:, 2]
    clear = np.abs(z) > 1e-6
    np.testing.assert_array_equal(f[clear], z[clear] >= 0)
    assert 0 < f.sum() < 360
    # A single pose, a pose inside the unit ball, and more poses than one request carries.
    assert ep.feasible([0.0, 0.0, 3.0, 0, 0, 0, 0]).tolist() == [True]
    assert ep.feasible([0.0, 0.0, 0.5, 0, 0, 0, 0]).tolist() == [False]
    many = np.tile(c, (40, 1))  # 14 400 poses: several batches of 4096, more than 1 MiB of JSON in all
    np.testing.assert_array_equal(ep.feasible(many), np.tile(f, 40))
    with pytest.raises(objview.InvalidRequest):
        client.request("POST", f"/v1/episodes/{ep.id}/feasible", body={"poses": [[1, 2, 3]]})
    with pytest.raises(objview.InvalidRequest):
        client.request(
            "POST", f"/v1/episodes/{ep.id}/feasible", body={"poses": [[1, 2, 3, 0, 0, 0, None]]}
        )
    assert ep.step == 0 and ep.status()["state"] == "running"


def test_payload_too_large(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-feasible")
    big = b'{"poses": [' + b",".join([b"[3.0,0.0,0.0,0.0,0.0,0.0,0.0]"] * 40000) + b"]}"
    assert len(big) > 1 << 20
    with pytest.raises(objview.PayloadTooLarge) as e:
        client.request("POST", f"/v1/episodes/{ep.id}/feasible", raw_body=big)
    assert e.value.status == 413


def test_episodes_belong_to_their_token(server, client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-owner")
    other = server.client(token=OTHER_TOKEN)
    with pytest.raises(objview.NotFound):
        other.episode_status(ep.id)
    with pytest.raises(objview.NotFound):
        other.act(ep.id, 0, {"type": "stop", "reason": "plan_end"})
    assert ep.status()["state"] == "running"


def test_results_and_methods(client):
    for obj in (0, 1):
        ep = client.create_episode("tiny", obj, budget=5, method="t-results", seed=11)
        ep.move(ep.candidates[5])
        ep.stop("plan_end")
    res = client.results("t-results")
    assert [r["uid"] for r in res] == ["cube", "cone"]  # finish order
    assert all(r["method"] == "t-results" and len(r["visited_poses"]) == 2 for r in res)
    assert all(r["seed"] == 11 for r in res)
    methods = {m["method"]: m["finished"] for m in client.methods()}
    assert methods["t-results"] == 2
    # JSON Lines: exactly one line per result, no blank lines.
    text = client.results_jsonl("t-results")
    assert text.endswith("\n") and text.count("\n") == 2, repr(text[-40:])
    with pytest.raises(objview.NotFound):
        client.results("no-such-method")
