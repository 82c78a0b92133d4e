"""Time limits: a planner that does not act in time loses the episode (exception / timeout)."""

from __future__ import annotations

import time

import pytest

import objview
from conftest import start_server


@pytest.fixture(scope="module")
def fast_server(objview_bin, pool, tmp_path_factory):
    root = tmp_path_factory.mktemp("server-timeouts")
    with start_server(objview_bin, pool, root, "--action-timeout", "1", "--start-timeout", "1") as s:
        yield s


def test_a_late_action_finds_the_episode_finished(fast_server):
    client = fast_server.client()
    ep = client.create_episode("tiny", 0, budget=5, method="t-timeout")
    assert ep.action_timeout_s == pytest.approx(1.0)
    ep.move(ep.candidates[0])  # in time
    time.sleep(2.5)
    with pytest.raises(objview.EpisodeFinished):
        ep.move(ep.candidates[1])
    obs = ep.refresh()
    assert obs.done and ep.done
    assert ep.terminal["source"] == "exception" and ep.terminal["reason"] == "timeout"
    res = ep.result()
    assert res["terminal_source"] == "exception" and res["terminal_reason"] == "timeout"
    assert len(res["visited_poses"]) == 2  # the views taken are scored
    assert res["checkpoints"]["terminal"]["views"] == 2


def test_a_late_first_action_finds_the_episode_finished(fast_server):
    client = fast_server.client()
    ep = client.create_episode("tiny", 1, budget=5, method="t-timeout")
    time.sleep(2.5)
    with pytest.raises(objview.EpisodeFinished):
        ep.stop("plan_end")
    st = ep.status()
    assert st["state"] == "finished" and st["terminal"]["reason"] == "timeout"
    # Attaching to a finished episode by id.
    again = client.episode(ep.id)
    assert again.done and again.terminal["reason"] == "timeout" and again.step == 0


def test_gym_step_after_the_server_ended_the_episode_terminates(fast_server):
    import json

    from objview.gym import ObjViewEnv

    env = ObjViewEnv(fast_server.client(), "tiny", budget=5, candidate_set="tammes-128",
                     method="t-timeout-gym")
    obs, info = env.reset(seed=0)
    time.sleep(2.5)  # the server ends the episode (start timeout 1 s)
    obs, reward, terminated, truncated, info = env.step(0)
    assert terminated and not truncated
    assert info["terminal"]["source"] == "exception" and info["terminal"]["reason"] == "timeout"
    assert json.loads(info["result_json"])["terminal_reason"] == "timeout"
    env.close()
