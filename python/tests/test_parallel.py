"""run_planner(workers=N): episodes run concurrently on one shared client, with the same results
as a sequential run; a failure aborts every episode of the run still going."""

from __future__ import annotations

import threading
import time

import pytest

import objview


class Concurrent(objview.Planner):
    """Waits in reset until `n` episodes are live at once (fails, not hangs, if they are not)."""

    barrier: threading.Barrier = threading.Barrier(1)
    threads: set = set()
    lock = threading.Lock()

    def reset(self, episode):
        with Concurrent.lock:
            Concurrent.threads.add(threading.get_ident())
        Concurrent.barrier.wait(timeout=60)
        self.moves = 0
        self.cands = episode.candidates
        self.ok = [i for i, f in enumerate(episode.feasible(self.cands)) if f]

    def act(self, observation, episode):
        if self.moves >= 3:
            return ("stop", "plan_end")
        i = self.ok[(episode.seed + 7 * self.moves) % len(self.ok)]
        self.moves += 1
        return ("move", self.cands[i])


@pytest.mark.parametrize("n", [2, 4])
def test_workers_run_episodes_concurrently(client, n):
    Concurrent.barrier = threading.Barrier(n)
    Concurrent.threads = set()
    objects = ["cube", "cone", "cube", "cone"][:n]
    kw = dict(budget=5, method=f"t-par-{n}", record_timings=False, eager_depth=False)
    par = objview.run_planner(client, Concurrent(), "tiny", objects=objects, workers=n,
                              seed=5, **kw)
    assert len(Concurrent.threads) == n  # n worker threads, all inside an episode at once
    assert [r["uid"] for r in par] == objects  # object order
    Concurrent.barrier = threading.Barrier(1)
    seq = objview.run_planner(client, Concurrent(), "tiny", objects=objects, seed=5, **kw)
    assert [r["visited_poses"] for r in par] == [r["visited_poses"] for r in seq]
    assert [r["checkpoints"] for r in par] == [r["checkpoints"] for r in seq]


class Episodes:
    ids: list = []
    started = threading.Barrier(3)


class SlowOrFailing(objview.Planner):
    def reset(self, episode):
        Episodes.ids.append(episode.id)
        Episodes.started.wait(timeout=60)  # all three episodes exist before any fails
        self.n = 0

    def act(self, observation, episode):
        self.n += 1
        if episode.object_id == "cone" and self.n == 2:
            raise RuntimeError("planner bug")
        time.sleep(0.3)
        return ("move", episode.candidates[self.n])


def test_a_failure_aborts_every_running_episode_of_the_run(client):
    Episodes.ids = []
    Episodes.started = threading.Barrier(3)
    with pytest.raises(RuntimeError, match="planner bug"):
        objview.run_planner(client, SlowOrFailing(), "tiny", objects=["cube", "cone", "cube"],
                            budget=30, method="t-par-fail", workers=3, eager_depth=False)
    assert len(Episodes.ids) == 3
    terminals = [client.episode_status(i)["terminal"] for i in Episodes.ids]
    assert all(t is not None for t in terminals)  # nothing left running
    assert all((t["source"], t["reason"]) == ("exception", "planner_error") for t in terminals)
    assert any("RuntimeError: planner bug" in t["detail"] for t in terminals)
    assert sum("Cancelled" in t["detail"] for t in terminals) == 2
