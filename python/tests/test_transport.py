"""Transport: keep-alive (one connection per thread), gzip, reconnecting after the server
closed an idle connection, the OBJVIEW_URL/OBJVIEW_TOKEN defaults, quiet logging."""

from __future__ import annotations

import gzip
import http.server
import json
import threading
import time

import pytest

import objview
from conftest import TOKEN, start_server


class Handler(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"  # keep-alive

    def setup(self):
        super().setup()
        with self.server.lock:
            self.server.connections += 1

    def log_message(self, *a):
        pass

    def do_GET(self):
        self.server.seen.append(dict(self.headers.items()))
        body = json.dumps({"status": "ok", "version": "x", "pad": "a" * 2000}).encode()
        gz = "gzip" in (self.headers.get("Accept-Encoding") or "")
        if gz:
            body = gzip.compress(body)
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        if gz:
            self.send_header("Content-Encoding", "gzip")
        self.send_header("Content-Length", str(len(body)))
        if self.server.close_after_each:
            self.send_header("Connection", "close")
            self.close_connection = True
        self.end_headers()
        self.wfile.write(body)


@pytest.fixture
def local_server():
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    srv.daemon_threads = True
    srv.lock = threading.Lock()
    srv.connections = 0
    srv.seen = []
    srv.close_after_each = False
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    yield srv
    srv.shutdown()
    srv.server_close()


def test_keep_alive_and_gzip(local_server):
    url = f"http://127.0.0.1:{local_server.server_address[1]}"
    c = objview.Client(url, token=None)
    for _ in range(10):
        assert c.health()["status"] == "ok"
    assert local_server.connections == 1 and c.connections_opened == 1
    assert all(h.get("Accept-Encoding") == "gzip" for h in local_server.seen)
    r = c.request("GET", "/v1/health")
    assert r.header("Content-Encoding") == "gzip" and json.loads(r.content)["pad"] == "a" * 2000

    # One connection per thread, reused by that thread.
    def work():
        for _ in range(5):
            c.health()

    threads = [threading.Thread(target=work) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert local_server.connections == 4 and c.connections_opened == 4
    c.close()
    c.health()
    assert local_server.connections == 5

    # A server that closes after each answer (Connection: close): the client opens a new
    # connection for the next request, no error (the first reuses the open one).
    local_server.close_after_each = True
    for _ in range(3):
        c.health()
    assert local_server.connections == 7 and c.connections_opened == 7


def test_reconnects_after_the_server_closed_an_idle_connection(objview_bin, pool, tmp_path):
    with start_server(objview_bin, pool, tmp_path, "--idle-timeout", "1") as srv:
        c = srv.client()
        assert c.splits()
        assert c.connections_opened == 1
        time.sleep(1.6)  # the server closes the idle keep-alive connection
        assert c.splits()  # sent again on a new connection
        assert c.connections_opened == 2
        ep = c.create_episode("tiny", 0, budget=5, method="t-idle")
        time.sleep(1.6)
        ep.move(ep.candidates[0])  # a POST after the idle close
        assert ep.step == 1


def test_the_real_server_gzips_and_keeps_the_connection(issue17_server):
    server = issue17_server
    c = server.client()
    r = c.request("GET", "/v1/candidate-sets/tammes-360")
    if r.header("Content-Encoding") is None:
        pytest.fail("the server did not gzip a 30 kB JSON answer to Accept-Encoding: gzip")
    assert r.header("Content-Encoding") == "gzip"
    assert len(json.loads(r.content)["poses"]) == 360
    ep = c.create_episode("tiny", 0, budget=5, method="t-gzip")
    d = ep.observation().depth
    assert d.shape == (512, 512)
    n = c.connections_opened
    for i in range(5):
        ep.move(ep.candidates[i])
    assert c.connections_opened == n  # every request on the same connection


def test_environment_variables(monkeypatch, server):
    monkeypatch.setenv("OBJVIEW_URL", server.url + "/")
    monkeypatch.setenv("OBJVIEW_TOKEN", TOKEN)
    c = objview.Client()
    assert c.url == server.url and c.token == TOKEN
    assert c.split("tiny")["objects"] == 2
    anon = objview.Client(token=None)  # explicit None wins over the environment
    assert anon.token is None
    with pytest.raises(objview.Unauthorized):
        anon.splits()
    assert objview.Client("http://example.invalid:1", token="x").token == "x"
    monkeypatch.delenv("OBJVIEW_URL")
    monkeypatch.delenv("OBJVIEW_TOKEN")
    c = objview.Client()
    assert c.url == "http://127.0.0.1:8080" and c.token is None
    with pytest.raises(ValueError):
        objview.Client("ftp://x")


def test_the_library_prints_nothing(client, capsys, caplog):
    import logging

    caplog.set_level(logging.INFO, logger="objview")

    class Stop(objview.Planner):
        def act(self, observation, episode):
            return ("stop", "plan_end")

    objview.run_planner(client, Stop(), "tiny", budget=5, method="t-quiet", progress=True,
                        eager_depth=False)
    with client.create_episode("tiny", 0, budget=5, method="t-quiet"):
        pass  # aborted: logged, not printed
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    msgs = [r.getMessage() for r in caplog.records]
    assert any(m.startswith("cube: ") for m in msgs) and any("aborted episode" in m for m in msgs)
