"""The server's cap on running episodes: a create beyond it raises ``TooManyEpisodes``, and a
place comes back when an episode ends."""

from __future__ import annotations

from typing import Iterator

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
