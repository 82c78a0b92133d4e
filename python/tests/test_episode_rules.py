"""Episode rules through the client: stale steps, invalid actions, the end of an episode."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import objview


def test_stale_step_changes_nothing_and_the_episode_goes_on(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    c = ep.candidates
    with pytest.raises(objview.StaleStep) as e:
        ep.move(c[1], step=3)
    assert e.value.status == 409 and e.value.code == "stale_step"
    st = ep.status()
    assert st["state"] == "running" and st["step"] == 0 and st["views"] == 1
    o = ep.move(c[1])
    assert o.step == 1
    with pytest.raises(objview.StaleStep):  # the old step again
        ep.move(c[2], step=0)
    with pytest.raises(objview.StaleStep):
        ep.stop("plan_end", step=0)
    assert ep.status()["step"] == 1
    o = ep.move(c[2])
    assert o.step == 2 and not o.done
    ep.stop("plan_end")
    assert len(ep.result()["visited_poses"]) == 3


def test_concurrent_actions_for_one_step_apply_once(server):
    client = server.client()
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    c = ep.candidates
    outcomes = []

    def send(i):
        try:
            client.act(ep.id, 0, {"type": "move", "pose": c[i].tolist()})
            outcomes.append("ok")
        except objview.StaleStep:
            outcomes.append("stale")

    threads = [threading.Thread(target=send, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(outcomes) == ["ok", "stale", "stale", "stale"]
    st = ep.status()
    assert st["step"] == 1 and st["views"] == 2


def test_request_shape_errors_leave_the_episode_running(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    path = f"/v1/episodes/{ep.id}/actions"
    with pytest.raises(objview.MalformedJSON):
        client.request("POST", path, raw_body=b"step=0")
    with pytest.raises(objview.InvalidRequest):
        client.request("POST", path, body={"action": {"type": "stop", "reason": "plan_end"}})
    with pytest.raises(objview.InvalidRequest):
        client.request("POST", path, body={"step": "0", "action": {"type": "move"}})
    with pytest.raises(objview.InvalidRequest):
        client.request("POST", path, body={"step": 0, "action": "stop"})
    st = ep.status()
    assert st["state"] == "running" and st["step"] == 0


@pytest.mark.parametrize(
    "action",
    [
        {"type": "stop", "reason": "bored"},
        {"type": "teleport", "pose": [3, 0, 0, 0, 0, 0, 0]},
        {"type": "move", "pose": [3, 0, 0, 0, 0, 0]},
        {"type": "move", "pose": [3, 0, 0, 0, 0, 0, "x"]},
        {"type": "move"},
    ],
    ids=["unknown-reason", "unknown-type", "six-numbers", "string", "no-pose"],
)
def test_malformed_actions_end_the_episode_as_invalid(client, action):
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    ep.move(ep.candidates[0])
    o = ep.act(action)
    assert o.done and ep.done
    assert ep.terminal["reason"] == "invalid_action", ep.terminal
    assert ep.terminal["source"] == "benchmark"
    res = ep.result()
    assert res["terminal_reason"] == "invalid_action"
    assert len(res["visited_poses"]) == 2  # views taken are kept and scored
    assert res["checkpoints"]["terminal"]["views"] == 2
    with pytest.raises(objview.EpisodeFinished) as e:
        ep.move(ep.candidates[1])
    assert e.value.status == 409 and e.value.code == "episode_finished"
    with pytest.raises(objview.EpisodeFinished):
        ep.stop("plan_end")


def test_non_finite_and_infeasible_moves_are_invalid_actions(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    o = ep.move(np.array([3.0, np.nan, 0, 0, 0, 0, 0]))  # sent as null
    assert o.done and ep.terminal["reason"] == "invalid_action"

    ep = client.create_episode("tiny", 0, view_space="hemi", budget=5, method="t-rules")
    c = ep.candidates
    bad = int(np.flatnonzero(c[:, 2] < -0.5)[0])
    assert not ep.feasible(c[bad])[0]
    o = ep.move(c[bad])
    assert o.done and ep.terminal["reason"] == "invalid_action"
    assert o.step == 0  # the move was not taken
    assert len(ep.result()["visited_poses"]) == 1


def test_fixed_budget_iterative_run_ends_by_itself(client):
    """Repeated poses are allowed; an iterative run ends at `enough_info` once K=5, 10, 30, 50
    and every MS@δ exist (budget checkpoints, not stops)."""
    ep = client.create_episode("tiny", 0, budget=5, method="t-rules")
    pose = ep.candidates[7]
    n = 0
    while not ep.done:
        ep.move(pose)
        n += 1
        assert n <= 128
    res = ep.result()
    assert res["terminal_reason"] in ("enough_info", "max_cap_reached"), res["terminal_reason"]
    assert {"K=5", "K=10", "K=30", "K=50", "terminal"} <= set(res["checkpoints"])
    # A repeated pose costs no path: the only travel is start → pose.
    pc = res["checkpoints"]["K=5"]["path_cost"]
    assert pc == pytest.approx(res["checkpoints"]["terminal"]["path_cost"])
