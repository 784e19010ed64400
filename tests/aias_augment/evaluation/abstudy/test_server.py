"""The server as raters and attackers meet it: a real uvicorn process, raw HTTP requests."""

import csv
import errno
import io
import json
import re
import sqlite3
import threading

import pytest

from aias_augment.evaluation.abstudy.build import build_study, load_study
from aias_augment.evaluation.abstudy.server import STATIC_DIR, create_app
from aias_augment.evaluation.abstudy.store import VoteStore
from tests.aias_augment.evaluation.abstudy.helpers import InProcessServer, Server, image_arms, request


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("abstudy_server")
    build_study(image_arms(tmp, 3), tmp / "study", seed=2)
    with Server(tmp / "study") as srv:
        yield srv, load_study(tmp / "study")


def _vote(srv, rater, pid, choice="left", **extra):
    return request(srv, "POST", "/api/vote", {"pair_id": pid, "choice": choice, "rater": rater, **extra})


def test_pages_static_and_no_external_resources(served):
    srv, _ = served
    for path in ("/", "/results", "/static/app.js", "/static/results.js", "/static/style.css"):
        st, body, h = request(srv, "GET", path)
        assert st == 200, path
        assert "default-src 'self'" in h["content-security-policy"]
        # nothing from a CDN: no absolute URL is referenced by the page or its assets
        assert not re.search(r"""(src|href|url)\s*[=(]\s*["']?(https?:)?//""", body), path
    for f in STATIC_DIR.iterdir():
        assert "http://" not in f.read_text() and "https://" not in f.read_text(), f
    assert request(srv, "GET", "/favicon.ico")[0] == 204
    assert request(srv, "GET", "/docs")[0] == 404  # the API docs load from a CDN: off


def test_rater_cookie_progress_and_next(served):
    srv, study = served
    assert request(srv, "GET", "/api/next")[0] == 400  # no rater yet
    st, body, h = request(srv, "POST", "/api/rater", {"name": "  Ann   Lee "})
    assert st == 200 and body == {"rater": "Ann Lee", "done": 0, "total": len(study.pairs)}
    cookie = h["set-cookie"].split(";")[0]
    assert "HttpOnly" in h["set-cookie"] and "SameSite=strict" in h["set-cookie"]
    st, me, _ = request(srv, "GET", "/api/me", headers={"Cookie": cookie})
    assert me["rater"] == "Ann Lee"
    st, nxt, _ = request(srv, "GET", "/api/next", headers={"Cookie": cookie})
    pair = nxt["pair"]
    assert st == 200 and pair["id"] in study.pairs and pair["kind"] == "image"
    assert pair["left"] == [f"/media/{pair['id']}/L/0"] and set(pair) == {"id", "kind", "fps", "left", "right"}
    # a vote with the cookie as the rater id; the next pair is another one
    st, body, _ = request(
        srv, "POST", "/api/vote", {"pair_id": pair["id"], "choice": "right", "ms": 900}, headers={"Cookie": cookie}
    )
    assert st == 201 and body["done"] == 1
    st, nxt2, _ = request(srv, "GET", "/api/next", headers={"Cookie": cookie})
    assert nxt2["pair"]["id"] != pair["id"] and nxt2["done"] == 1
    # each rater gets their own order
    orders = {request(srv, "GET", f"/api/next?rater=order{i}")[1]["pair"]["id"] for i in range(8)}
    assert len(orders) > 1
    assert request(srv, "POST", "/api/rater", {"name": "<script>"})[0] == 422
    assert request(srv, "POST", "/api/rater", {"name": "   "})[0] == 422


def test_media_bytes_and_unknown_files(served):
    srv, study = served
    pid, pair = next(iter(study.pairs.items()))
    for side, key in (("L", "left"), ("R", "right")):
        st, body, h = request(srv, "GET", f"/media/{pid}/{side}/0")
        assert st == 200 and h["content-type"] == "image/png"
        assert body == (study.root / pair[key][0]).read_bytes()
    for path in (
        f"/media/{pid}/X/0",
        f"/media/{pid}/L/1",
        f"/media/{pid}/L/-1",
        f"/media/{pid}/L/abc",
        "/media/ffffffffffff/L/0",
        "/media/nothex/L/0",
        f"/media/{pid}/L/0/extra",
        "/static/nope.js",
        f"/media/{pid}/L/%C2%B2",
        f"/media/{pid}/L/%EF%BC%90",
        f"/media/{pid}/L/%D9%A0",  # '²', '０', '٠'
        f"/media/{pid}/L/0000000",
        f"/media/{pid}/L/%200",
        f"/media/{pid}/L/+0",
    ):
        st, body, _ = request(srv, "GET", path)
        assert st == 404, path
        assert "detail" in body if isinstance(body, dict) else True


@pytest.mark.parametrize(
    "path",
    [
        "/static/../key.json",
        "/static/%2e%2e/key.json",
        "/static/..%2fkey.json",
        "/static/%2e%2e%2fserver.py",
        "/static/../../../../etc/passwd",
        "/static/..%2f..%2f..%2f..%2fetc%2fpasswd",
        "/static//etc/passwd",
        "/media/../key.json",
        "/media/%2e%2e/%2e%2e/key.json",
        "/media/{pid}/L/..%2f..%2fkey.json",
        "/media/{pid}/..%2f..%2fkey.json/0",
        "/media/..%2fkey.json/L/0",
        "/../key.json",
        "/%2e%2e/key.json",
        "/key.json",
        "/study.json",
        "/votes.sqlite",
        "/media/",
        "/static/%00",
        "/static/..\\key.json",
    ],
)
def test_path_traversal_is_refused(served, path):
    srv, study = served
    pid = next(iter(study.pairs))
    st, body, _ = request(srv, "GET", path.format(pid=pid))
    assert st in (400, 404), (path, st)
    text = body if isinstance(body, str) else json.dumps(body) if isinstance(body, dict) else repr(body)
    assert "naive_paste" not in text and "root:" not in text and "import" not in text


def test_malformed_unknown_and_repeated_votes(served):
    srv, study = served
    pid = sorted(study.pairs)[0]
    assert _vote(srv, "mal", pid, "tie")[0] == 201
    st, body, _ = _vote(srv, "mal", pid, "left")
    assert st == 409 and body["stored_choice"] == "tie" and "already voted" in body["detail"]
    assert _vote(srv, "mal", "ffffffffffff")[0] == 404
    assert _vote(srv, "mal", "../../key.json")[0] == 404
    bad = [
        {"pair_id": pid, "choice": "up", "rater": "mal2"},
        {"pair_id": pid, "rater": "mal2"},
        {"choice": "left", "rater": "mal2"},
        {"pair_id": pid, "choice": "left", "rater": "mal2", "arm": "full"},
        {"pair_id": pid, "choice": "left", "rater": "mal2", "ms": -5},
        {"pair_id": pid, "choice": "left", "rater": "bad/rater"},
        {"pair_id": 5, "choice": "left", "rater": "x"},
        [pid, "left"],
        "left",
    ]
    for b in bad:
        assert request(srv, "POST", "/api/vote", b)[0] == 422, b
    for raw in (b"{not json", b"", b"\xff\xfe"):
        assert request(srv, "POST", "/api/vote", raw=raw, headers={"Content-Type": "application/json"})[0] == 422
    st, body, _ = request(srv, "POST", "/api/vote", {"pair_id": pid, "choice": "left"})
    assert st == 400 and "rater" in body["detail"]
    assert request(srv, "GET", "/api/vote")[0] == 405
    # none of the refused requests stored anything
    votes = [v for v in VoteStore(study.root / "votes.sqlite").votes() if v["rater"].startswith("mal")]
    assert [(v["rater"], v["choice"]) for v in votes] == [("mal", "tie")]


def test_concurrent_raters_lose_no_votes(served):
    srv, study = served
    pids = sorted(study.pairs)
    n_raters = 8
    results, errors = [], []

    def rater(r):
        try:
            for i, pid in enumerate(pids):
                st, _, _ = _vote(srv, f"conc{r}", pid, ("left", "right", "tie")[(r + i) % 3], ms=100 + i)
                results.append(st)
            st, _, _ = _vote(srv, f"conc{r}", pids[0], "left")  # a repeat, mid-stream of the others
            results.append(st)
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=rater, args=(r,)) for r in range(n_raters)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors
    assert results.count(201) == n_raters * len(pids) and results.count(409) == n_raters
    stored = [v for v in VoteStore(study.root / "votes.sqlite").votes() if v["rater"].startswith("conc")]
    assert len(stored) == n_raters * len(pids)
    assert {(v["rater"], v["pair_id"]) for v in stored} == {(f"conc{r}", p) for r in range(n_raters) for p in pids}
    assert all(
        v["choice"] == ("left", "right", "tie")[(int(v["rater"][4:]) + pids.index(v["pair_id"])) % 3] for v in stored
    )
    # the exports see them too
    st, text, h = request(srv, "GET", "/api/votes.csv")
    assert st == 200 and h["content-type"].startswith("text/csv")
    rows = [r for r in csv.DictReader(io.StringIO(text)) if r["rater"].startswith("conc")]
    assert len(rows) == n_raters * len(pids)
    assert all(
        r["preferred_arm"] == {"left": r["left_arm"], "right": r["right_arm"]}.get(r["choice"], "") for r in rows
    )
    st, rep, _ = request(srv, "GET", "/api/results")
    assert st == 200 and rep["votes"] >= n_raters * len(pids)
    st, text, _ = request(srv, "GET", "/api/results.csv")
    assert text.splitlines()[0].startswith("method,opponent,pairs,votes,wins")


def test_votes_survive_a_killed_server(tmp_path):
    build_study(image_arms(tmp_path, 2), tmp_path / "study")
    study = load_study(tmp_path / "study")
    pids = sorted(study.pairs)
    with Server(tmp_path / "study") as srv:
        for pid in pids[:3]:
            assert _vote(srv, "ann", pid, "right")[0] == 201
        srv.stop(kill=True)  # SIGKILL: no shutdown hook runs
    # read back with plain sqlite3, before any server touches the file again
    con = sqlite3.connect(tmp_path / "study" / "votes.sqlite")
    assert con.execute("SELECT COUNT(*) FROM votes WHERE rater = 'ann'").fetchone()[0] == 3
    con.close()
    with Server(tmp_path / "study") as srv:
        assert request(srv, "GET", "/healthz")[1]["votes"] == 3
        assert _vote(srv, "ann", pids[0], "left")[0] == 409
        assert request(srv, "GET", "/api/me?rater=ann")[1]["done"] == 3
        st, nxt, _ = request(srv, "GET", "/api/next?rater=ann")
        assert nxt["pair"]["id"] in pids[3:]
        assert _vote(srv, "ann", pids[3], "tie")[0] == 201
        srv.stop()  # SIGTERM: a graceful stop
    assert VoteStore(tmp_path / "study" / "votes.sqlite").count() == 4


@pytest.mark.parametrize(
    "error", [OSError(errno.ENOSPC, "No space left on device"), sqlite3.OperationalError("database or disk is full")]
)
def test_a_vote_the_store_cannot_write_is_a_json_503_and_not_recorded(tmp_path, monkeypatch, error):
    """The disk is full when a vote is written: the rater gets the documented JSON error (503, ``recorded``
    false, the reason), nothing is stored, and the same vote is taken once the store can be written again."""
    build_study(image_arms(tmp_path, 2), tmp_path / "study")
    app = create_app(tmp_path / "study")
    pid = sorted(app.state.study.pairs)[0]

    def disk_full(*args, **kwargs):
        raise error

    with InProcessServer(app) as srv:
        monkeypatch.setattr(app.state.store, "add_vote", disk_full)
        st, body, h = _vote(srv, "ann", pid)
        assert st == 503 and h["content-type"] == "application/json"
        assert body["recorded"] is False and "cannot write its vote store" in body["detail"]
        assert ("No space left on device" if isinstance(error, OSError) else "disk is full") in body["detail"]
        monkeypatch.undo()
        assert request(srv, "GET", "/api/me?rater=ann")[1]["done"] == 0
        assert _vote(srv, "ann", pid)[0] == 201


# ------------------------------------------------------------------------- what the guard refuses before a route
@pytest.mark.parametrize(
    "raw",
    [
        b'{"pair_id": "P", "choice": "left", "rater": "nan1", "ms": NaN}',
        b'{"pair_id": "P", "choice": "left", "rater": "nan2", "ms": Infinity}',
        b'{"pair_id": "P", "choice": "left", "rater": "nan3", "ms": -Infinity}',
        b'{"pair_id": "P", "choice": "left", "rater": "nan4", "ms": 1e400}',
        b'{"pair_id": NaN, "choice": "left", "rater": "nan5"}',
    ],
    ids=["NaN", "Infinity", "-Infinity", "1e400", "NaN-pair"],
)
def test_non_finite_json_is_a_422_not_a_500(served, raw):
    srv, study = served
    raw = raw.replace(b'"P"', json.dumps(sorted(study.pairs)[1]).encode())
    st, body, h = request(srv, "POST", "/api/vote", raw=raw, headers={"Content-Type": "application/json"})
    assert st == 422 and "JSON" in body["detail"], (st, body)
    assert "default-src 'self'" in h["content-security-policy"]
    assert not [v for v in VoteStore(study.root / "votes.sqlite").votes() if v["rater"].startswith("nan")]
    assert request(srv, "GET", "/healthz")[0] == 200


def test_body_over_the_cap_is_413_from_its_length_without_reading_it(served):
    import socket

    from aias_augment.evaluation.abstudy.guard import MAX_BODY_BYTES

    srv, _ = served
    # the header claims 200 MB and no byte of it follows: an answer proves the server did not wait to read it
    with socket.create_connection((srv.host, srv.port), timeout=10) as s:
        s.sendall(
            f"POST /api/vote HTTP/1.1\r\nHost: {srv.host}:{srv.port}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {200 * 2**20}\r\n\r\n".encode()
        )
        head = s.recv(4096).decode("latin-1")
    assert head.startswith("HTTP/1.1 413"), head
    big = b'{"pair_id": "' + b"x" * MAX_BODY_BYTES + b'"}'
    st, body, _ = request(srv, "POST", "/api/rater", raw=big, headers={"Content-Type": "application/json"})
    assert st == 413 and str(MAX_BODY_BYTES) in body["detail"]


def test_chunked_body_over_the_cap_is_413(served):
    import http.client

    srv, _ = served
    # The server answers 413 and closes as soon as the cap is passed; a client still writing its later chunks then
    # meets a closed socket (a transport race, not the server's answer): such an attempt is made again.
    for attempt in range(5):
        con = http.client.HTTPConnection(srv.host, srv.port, timeout=30)
        try:
            con.request(
                "POST",
                "/api/vote",
                body=iter([b"{" + b" " * 16384] * 8),  # 128 KiB in chunks, no Content-Length
                headers={"Content-Type": "application/json"},
                encode_chunked=True,
            )
            resp = con.getresponse()
            status, detail = resp.status, json.loads(resp.read())["detail"]
        except (BrokenPipeError, ConnectionResetError):
            if attempt == 4:
                raise
            continue
        finally:
            con.close()
        assert status == 413 and "request body over" in detail
        return


def test_body_under_the_cap_reaches_the_route(served):
    srv, study = served
    pad = " " * 60000  # JSON whitespace: a 60 KB body that is a valid vote
    raw = f'{{"pair_id": "{sorted(study.pairs)[2]}", "choice": "tie", "rater": "padded"{pad}}}'.encode()
    st, body, _ = request(srv, "POST", "/api/vote", raw=raw, headers={"Content-Type": "application/json"})
    assert st == 201 and body["done"] == 1


@pytest.mark.parametrize(
    "host, served_ok",
    [
        ("{host}:{port}", True),
        ("localhost:{port}", True),
        ("LOCALHOST:{port}", True),
        ("127.0.0.1:{port}", True),
        ("attacker.example:{port}", False),
        ("attacker.example", False),
        ("127.0.0.1:{other}", False),
        ("", False),
    ],
)
def test_only_the_served_host_is_answered(served, host, served_ok):
    srv, _ = served
    host = host.format(host=srv.host, port=srv.port, other=srv.port + 1)
    st, body, _ = request(srv, "GET", "/api/study", headers={"Host": host})
    if served_ok:
        assert st == 200 and body["pairs"] > 0
    else:
        assert st == 400 and "does not answer for host" in body["detail"]
        st, _, _ = request(srv, "POST", "/api/rater", {"name": "rebound"}, headers={"Host": host})
        assert st == 400


def test_host_names_of_a_loopback_and_a_wildcard_bind():
    import socket

    from aias_augment.evaluation.abstudy.guard import host_names

    assert host_names("127.0.0.1", 8000) == {"127.0.0.1:8000", "localhost:8000", "[::1]:8000"}
    assert "[::1]:9" in host_names("::1", 9)
    every = host_names("0.0.0.0", 8000)
    assert f"{socket.gethostname().lower()}:8000" in every and "localhost:8000" in every
