"""Abandoned episodes: abort, the with-block, the planner loop and the environment leave nothing
running on the server; orphans can be listed and aborted; stop reasons are checked here."""

from __future__ import annotations

import warnings

import pytest
from gymnasium.utils.env_checker import check_env

import objview
from conftest import OTHER_TOKEN, TOKEN
from objview.gym import ObjViewEnv


def state(client, ep_id):
    return client.episode_status(ep_id)


def assert_aborted(client, ep_id, detail_part=None):
    st = state(client, ep_id)
    assert st["state"] == "finished", st
    t = st["terminal"]
    assert (t["source"], t["reason"]) == ("exception", "planner_error"), t
    if detail_part is not None:
        assert detail_part in (t.get("detail") or ""), t


def test_episode_abort(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-abort")
    ep.move(ep.candidates[3])
    o = ep.abort("gave up")
    assert o.done and ep.done and ep.terminal["reason"] == "planner_error"
    assert_aborted(client, ep.id, "gave up")
    res = ep.result()
    assert res["terminal_source"] == "exception" and len(res["visited_poses"]) == 2  # scored
    assert ep.abort("again").done  # a finished episode is left as it is


def test_with_block_aborts_on_exception_interrupt_and_early_exit(client):
    with client.create_episode("tiny", 0, budget=5, method="t-abort") as ep:
        ep.move(ep.candidates[1])
        ep.stop("plan_end")
    assert client.episode_status(ep.id)["terminal"]["reason"] == "plan_end"  # not touched

    with pytest.raises(RuntimeError):
        with client.create_episode("tiny", 0, budget=5, method="t-abort") as ep1:
            raise RuntimeError("planner bug")
    assert_aborted(client, ep1.id, "RuntimeError: planner bug")

    with pytest.raises(KeyboardInterrupt):
        with client.create_episode("tiny", 1, budget=5, method="t-abort") as ep2:
            ep2.move(ep2.candidates[2])
            raise KeyboardInterrupt
    assert_aborted(client, ep2.id, "KeyboardInterrupt")

    with client.create_episode("tiny", 1, budget=5, method="t-abort") as ep3:
        pass  # left before the end
    assert_aborted(client, ep3.id)


class Failing(objview.Planner):
    def __init__(self, exc, after=1):
        self.exc, self.after = exc, after
        self.episodes = []

    def reset(self, episode):
        self.episodes.append(episode)
        self.n = 0

    def act(self, observation, episode):
        if self.n >= self.after:
            raise self.exc
        self.n += 1
        return ("move", episode.candidates[self.n])


@pytest.mark.parametrize("exc", [ValueError("bad planner"), KeyboardInterrupt()])
def test_run_planner_aborts_on_any_exception(client, exc):
    p = Failing(exc)
    with pytest.raises(type(exc)):
        objview.run_planner(client, p, "tiny", budget=5, method="t-abort-loop", eager_depth=False)
    (ep,) = p.episodes
    assert_aborted(client, ep.id, type(exc).__name__)
    assert len(ep.result()["visited_poses"]) == 2


def test_stop_reason_typo_raises_here_and_changes_nothing(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-abort")
    with pytest.raises(ValueError, match="plan_ned"):
        ep.stop("plan_ned")
    assert state(client, ep.id)["state"] == "running"  # nothing was sent

    class Typo(objview.Planner):
        def act(self, observation, episode):
            return ("stop", "plan-end")

    with pytest.raises(ValueError, match="plan-end"):
        objview.run_episode(Typo(), ep)
    assert_aborted(client, ep.id, "ValueError")


def test_gym_reset_and_close_abort_the_running_episode(server):
    env = ObjViewEnv(server.url, "tiny", token=TOKEN, budget=5, candidate_set="tammes-128",
                     method="t-abort-gym")
    env.reset(seed=0)
    first = env.episode
    env.step(0)
    env.reset()
    assert_aborted(env.client, first.id, "reset()")
    second = env.episode
    env.close()
    assert_aborted(env.client, second.id, "close()")
    env.close()  # twice is fine


def test_list_episodes_and_abort_orphans(issue17_server):
    server = issue17_server
    client = server.client()
    other = server.client(token=OTHER_TOKEN)
    a = client.create_episode("tiny", 0, budget=5, method="t-orphan-a")
    b = client.create_episode("tiny", 1, budget=5, method="t-orphan-b")
    done = client.create_episode("tiny", 0, budget=5, method="t-orphan-a")
    done.stop("plan_end")
    theirs = other.create_episode("tiny", 0, budget=5, method="t-orphan-a")

    running = {e["episode_id"]: e for e in client.list_episodes(state="running")}
    assert a.id in running and b.id in running and done.id not in running
    assert theirs.id not in running  # token-scoped
    e = running[a.id]
    assert (e["split"], e["object"], e["method"], e["state"], e["step"]) == (
        "tiny", "cube", "t-orphan-a", "running", 0)
    assert "created_at" in e
    finished = {e["episode_id"] for e in client.list_episodes(state="finished")}
    assert done.id in finished and a.id not in finished
    only_a = {e["episode_id"] for e in client.list_episodes(state="running", method="t-orphan-a")}
    assert a.id in only_a and b.id not in only_a

    assert client.abort_orphans(method="t-orphan-a") == [a.id]
    assert_aborted(client, a.id, "orphan")
    assert state(client, b.id)["state"] == "running"
    assert b.id in client.abort_orphans()
    assert client.list_episodes(state="running") == []
    assert other.episode_status(theirs.id)["state"] == "running"  # not this token's
    other.abort_orphans()


def test_check_env_leaves_no_running_episode(issue17_server):
    server = issue17_server
    client = server.client()
    client.abort_orphans(method="t-gym-check-clean")
    env = ObjViewEnv(client, "tiny", budget=5, candidate_set="tammes-128",
                     method="t-gym-check-clean")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # unbounded Boxes, no spec
        check_env(env)
    running = client.list_episodes(state="running", method="t-gym-check-clean")
    # check_env resets many times; only the environment's current episode may still run…
    assert [e["episode_id"] for e in running] == [env.episode.id]
    env.close()
    # …and close() ends it.
    assert client.list_episodes(state="running", method="t-gym-check-clean") == []
    assert len(client.list_episodes(state="finished", method="t-gym-check-clean")) >= 3
