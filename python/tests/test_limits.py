"""The server's cap on running episodes: a create beyond it raises ``TooManyEpisodes``, and a
place comes back when an episode ends."""

from __future__ import annotations

import time
from typing import Any, Iterator

import pytest

import objview
from conftest import OTHER_TOKEN, Server, start_server


@pytest.fixture(scope="module")
def capped_server(objview_bin, pool, tmp_path_factory) -> Iterator[Server]:
    root = tmp_path_factory.mktemp("server-limits")
    with start_server(objview_bin, pool, root, "--max-running", "2", "--max-running-per-token", "1") as s:
        yield s


def test_creates_beyond_the_caps_raise_too_many_episodes(capped_server: Server) -> None:
    main = capped_server.client()
    other = objview.Client(capped_server.url, token=OTHER_TOKEN)
    first = main.create_episode("tiny", 0, budget=5, method="t-limits")
    with pytest.raises(objview.TooManyEpisodes) as e:  # this token's one place is taken
        main.create_episode("tiny", 0, budget=5, method="t-limits")
    assert e.value.status == 429 and "--max-running-per-token 1" in e.value.message
    second = other.create_episode("tiny", 0, budget=5, method="t-limits")
    first.abort("done with it")  # its place comes back
    again = main.create_episode("tiny", 0, budget=5, method="t-limits")
    for ep in (second, again):
        ep.abort("cleanup")


class SlowStart(objview.Planner):
    """Holds its episode a second before two moves, so that two workers overlap."""

    def reset(self, episode: Any) -> None:
        time.sleep(1.0)
        self.cands = episode.candidates
        self.ok = [i for i, f in enumerate(episode.feasible(self.cands)) if f]
        self.moves = 0

    def act(self, observation: Any, episode: Any) -> Any:
        if self.moves >= 2:
            return ("stop", "plan_end")
        self.moves += 1
        return ("move", self.cands[self.ok[self.moves]])


def test_run_planner_waits_for_a_place_on_a_full_server(capped_server: Server) -> None:
    # One place for this token, two workers: the second waits instead of failing the run.
    client = capped_server.client()
    kw: Any = dict(budget=5, method="t-limits-wait", record_timings=False, eager_depth=False)
    t = time.monotonic()
    res = objview.run_planner(client, SlowStart(), "tiny", objects=[0, 1], workers=2, **kw)
    assert [r["terminal_reason"] for r in res] == ["plan_end", "plan_end"]
    assert time.monotonic() - t >= 2.0  # the episodes ran one after the other
    seq = objview.run_planner(client, SlowStart(), "tiny", objects=[0, 1], **kw)
    assert [r["visited_poses"] for r in res] == [r["visited_poses"] for r in seq]
