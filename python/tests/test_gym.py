"""The Gymnasium environment: check_env, a full episode, continuous poses, object choice."""

from __future__ import annotations

import json
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import objview
from conftest import TOKEN
from objview.gym import ObjViewEnv


def make(server, **kw):
    kw.setdefault("budget", 5)
    kw.setdefault("candidate_set", "tammes-128")
    return ObjViewEnv(server.url, "tiny", token=TOKEN, **kw)


class RecordingClient(objview.Client):
    """Keeps the ids of the episodes it creates."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.created = []

    def create_episode(self, *a, **kw):
        ep = super().create_episode(*a, **kw)
        self.created.append(ep.id)
        return ep


def test_check_env_passes_and_leaves_no_running_episode(server):
    client = RecordingClient(server.url, token=TOKEN)
    env = ObjViewEnv(client, "tiny", budget=5, candidate_set="tammes-128", method="t-gym-check")
    with warnings.catch_warnings():
        # Expected warnings only: the unbounded Boxes (depth ≥ 0, pose) and the missing spec
        # of an environment built without gymnasium.make (no alternative render modes).
        warnings.simplefilter("ignore", UserWarning)
        check_env(env)
    assert len(client.created) >= 3  # check_env resets many times…
    states = {i: client.episode_status(i)["state"] for i in client.created}
    # …and every episode but the environment's current one has been ended (aborted at reset).
    assert [i for i, st in states.items() if st == "running"] == [env.episode.id]
    env.close()
    assert all(client.episode_status(i)["state"] == "finished" for i in client.created)


def test_spaces_and_a_full_episode(server):
    env = make(server, method="t-gym", view_space="hemi")
    assert env.action_space == gymnasium.spaces.Discrete(129)
    assert env.stop_action == 128
    obs, info = env.reset(seed=5)
    assert obs in env.observation_space
    assert obs["depth"].shape == (512, 512) and obs["depth"].dtype == np.float32
    assert obs["pose"].shape == (7,) and obs["mask"].shape == (128,)
    assert info["step"] == 0 and info["object_id"] == "cube"
    # The mask is the view space's feasibility of the candidates (hemi: z ≥ 0).
    z = env.candidates[:, 2]
    clear = np.abs(z) > 1e-6
    np.testing.assert_array_equal(obs["mask"][clear].astype(bool), z[clear] >= 0)
    assert 0.0 < obs["depth"][256, 256] < 3.0

    order = np.flatnonzero(obs["mask"])
    steps = 0
    terminated = False
    while not terminated:
        action = int(order[steps % len(order)]) if steps < 3 else env.stop_action
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        assert reward == 0.0 and truncated is False
        assert obs in env.observation_space
        if not terminated:
            assert info["step"] == steps and "result_json" not in info and "terminal" not in info
            np.testing.assert_array_equal(obs["pose"], env.candidates[action])
    assert steps == 4
    assert info["terminal"]["reason"] == "plan_end"
    res = json.loads(info["result_json"])
    assert res == env.result
    assert res["uid"] == "cube" and res["method"] == "t-gym" and res["family"] == "learned"
    assert res["view_space"] == "hemi" and len(res["visited_poses"]) == 4
    assert res["checkpoints"]["terminal"]["views"] == 4
    env.close()


def test_continuous_pose_actions_objects_and_reward_hook(server):
    calls = []

    def reward_fn(env, obs, info):
        calls.append(info["step"])
        if "result_json" not in info:
            return 0.0
        return float(json.loads(info["result_json"])["checkpoints"]["terminal"]["sc"]["0.02"])

    env = make(server, method="t-gym", reward_fn=reward_fn, objects=["cone", 0])
    _, info = env.reset(seed=1)
    assert info["object_id"] == "cone"
    _, info = env.reset()
    assert info["object_id"] == "cube"
    _, info = env.reset()
    assert info["object_id"] == "cone"  # the cycle wraps
    _, info = env.reset(options={"object": "cube"})
    assert info["object_id"] == "cube"

    pose = np.array([0.0, -3.0, 0.5, 0.0, 0.0, 0.1, 0.3])
    obs, r, term, trunc, info = env.step(pose)
    assert not term and info["step"] == 1 and r == 0.0
    np.testing.assert_array_equal(obs["pose"], pose)
    obs, r, term, trunc, info = env.step(env.stop_action)
    assert term and 0.0 < r <= 1.0 and calls == [1, 1]
    with pytest.raises(ValueError):
        env.step(env.stop_action + 1)
    env.close()


def test_gymnasium_make(server):
    env = gymnasium.make("objview/ObjView-v0", url=server.url, split="tiny", token=TOKEN,
                         budget=5, candidate_set="tammes-128", method="t-gym")
    obs, info = env.reset(seed=0)
    assert obs["depth"].shape == (512, 512)
    obs, r, term, trunc, info = env.step(env.unwrapped.stop_action)
    assert term and json.loads(info["result_json"])["terminal_reason"] == "plan_end"
    env.close()


def test_info_action_mask_intrinsics_candidates(server):
    env = make(server, method="t-gym", view_space="hemi")
    obs, info = env.reset(seed=0)
    am = info["action_mask"]
    assert am.dtype == np.int8 and am.shape == (env.action_space.n,)
    assert am[env.stop_action] == 1  # the last action (index N) is the stop
    np.testing.assert_array_equal(am[:-1], obs["mask"])
    assert 0 < am[:-1].sum() < 128
    for _ in range(50):
        a = env.action_space.sample(mask=info["action_mask"])
        assert am[a] == 1
    assert info["intrinsics"] == env.episode.intrinsics and info["intrinsics"]["width"] == 512
    np.testing.assert_array_equal(info["candidates"], env.candidates)
    _, _, _, _, info = env.step(int(np.flatnonzero(am[:-1])[0]))
    np.testing.assert_array_equal(info["action_mask"], am)
    env.close()


def test_max_moves_stops_with_plan_end(server):
    env = make(server, method="t-gym-max", max_moves=2)
    obs, info = env.reset(seed=0)
    ok = np.flatnonzero(obs["mask"])
    _, _, term, _, info = env.step(int(ok[0]))
    assert not term
    _, _, term, _, info = env.step(int(ok[1]))
    assert term and info["terminal"]["reason"] == "plan_end"
    res = json.loads(info["result_json"])
    assert len(res["visited_poses"]) == 3 and res["terminal_source"] == "algorithm_stop"
    with pytest.raises(ValueError):
        make(server, max_moves=0)
    env.close()


def test_budget_alone_does_not_stop_after_k_moves(server):
    env = make(server, method="t-gym-budget")
    obs, _ = env.reset(seed=0)
    ok = np.flatnonzero(obs["mask"])
    for i in range(6):  # budget=5 and an iterative run: the sixth move is accepted
        _, _, term, _, info = env.step(int(ok[i]))
        if term:
            break
    assert info["step"] == 6 and not term
    env.close()


def test_import_objview_registers_the_env():
    import subprocess
    import sys

    code = ("import sys, gymnasium, objview; "
            "assert 'objview/ObjView-v0' in gymnasium.registry; "
            "assert 'objview.gym' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_vector_env_shards_and_seeds(server):
    from gymnasium.vector import SyncVectorEnv

    n = 2
    venv = SyncVectorEnv([
        (lambda i=i: make(server, method="t-gym-vec", shard=(i, n), max_moves=1))
        for i in range(n)
    ])
    obs, infos = venv.reset(seed=3)
    assert list(infos["object_id"]) == ["cube", "cone"]  # not both object 0
    assert [e.base_seed for e in venv.envs] == [3, 3]  # seed s - i: the same benchmark seed
    assert obs["depth"].shape == (n, 512, 512)
    ids = [e.episode.id for e in venv.envs]
    masks = infos["action_mask"]
    actions = np.array([int(np.flatnonzero(m[:-1])[0]) for m in masks])
    obs, rew, term, trunc, infos = venv.step(actions)
    assert term.tolist() == [True, True]
    results = [json.loads(s) for s in infos["result_json"]]  # a flat string per env
    assert [r["uid"] for r in results] == ["cube", "cone"]
    assert [r["seed"] for r in results] == [3, 3]
    assert list(infos["terminal"]["reason"]) == ["plan_end", "plan_end"]
    # The next reset continues each shard's cycle.
    obs, rew, term, trunc, infos = venv.step(actions)  # autoreset step
    assert list(infos["object_id"]) == ["cube", "cone"]
    running = [e.episode.id for e in venv.envs]
    venv.close()
    client = server.client()
    for ep_id in ids + running:
        assert client.episode_status(ep_id)["state"] == "finished"
    with pytest.raises(ValueError):
        make(server, shard=(2, 2))
