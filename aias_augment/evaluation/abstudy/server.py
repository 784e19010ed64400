"""The study server: FastAPI on uvicorn, localhost by default. Plain HTML/JS/CSS from ``static/``; nothing from a CDN
(the interactive API docs, which load from one, are off, and a Content-Security-Policy of 'self' makes the browser
refuse anything else).

Routes (all errors are JSON ``{"detail": ...}``):

    GET  /                          the rating page          GET  /results            the results page
    GET  /static/{file}             page assets              GET  /media/{pair}/{L|R}/{i}   an image or clip frame
    GET  /api/study                 title, kind, number of pairs
    POST /api/rater  {name}         sets the rater cookie    GET  /api/me             rater, votes done, total
    GET  /api/next                  the rater's next pair (each rater gets the pairs in their own shuffled order)
    POST /api/vote   {pair_id, choice: left|right|tie, rater?, ms?}
                     201 stored; 400 no rater; 404 unknown pair; 409 already voted; 422 malformed;
                     503 not stored, ``"recorded": false`` (the vote store cannot be written: disk full, I/O error)
    GET  /api/results               the report (JSON)        GET  /api/results.csv, /api/votes.csv   CSV exports
    GET  /healthz

Refused before any route (``guard.py``): a ``Host`` other than the address served (400), a body over 64 KiB (413),
JSON with NaN/Infinity or an overflowing number (422).

The rater is the ``rater`` field of a vote, else the ``rater`` query parameter, else the cookie set by
``/api/rater``.
"""

from __future__ import annotations

import hashlib
import logging
import random
import re
import socket
import sqlite3
import sys
from pathlib import Path
from typing import Literal
from urllib.parse import quote, unquote

try:
    from fastapi import FastAPI, HTTPException, Request
    from fastapi.responses import FileResponse, JSONResponse, Response
    from fastapi.staticfiles import StaticFiles
    from pydantic import BaseModel, ConfigDict, Field
except ImportError as exc:  # the web app's dependencies are an extra: the pipeline does not need them
    raise ImportError(f"the A/B study server needs its extra: pip install 'aias-augment[abstudy]' ({exc})") from exc

from aias_augment.evaluation.abstudy.build import MEDIA_TYPES, PAIR_ID_RE, load_study
from aias_augment.evaluation.abstudy.guard import RequestGuard, host_names
from aias_augment.evaluation.abstudy.report import compute_report, results_csv, votes_csv
from aias_augment.evaluation.abstudy.store import DuplicateVote, VoteStore

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).parent / "static"
COOKIE = "abstudy_rater"
RATER_RE = re.compile(r"^[\w][\w .@+'-]{0,63}$")
INDEX_RE = re.compile(r"[0-9]{1,6}")  # ASCII digits: str.isdigit() is also true of '²', which int() refuses
CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; media-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'self'"
)


class RaterIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=64)


class VoteIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    pair_id: str = Field(min_length=1, max_length=64)
    choice: Literal["left", "right", "tie"]
    rater: str | None = Field(default=None, min_length=1, max_length=64)
    ms: int | None = Field(default=None, ge=0, le=24 * 3600 * 1000)


def clean_rater(name: str | None) -> str | None:
    """A rater id: 1-64 characters, letters/digits first, then letters, digits, space and ``.@+'-``; None if empty."""
    if name is None:
        return None
    name = " ".join(name.split())
    if not name:
        return None
    if not RATER_RE.match(name):
        raise HTTPException(422, "rater id: 1-64 letters, digits, spaces or .@+'- (starting with a letter or digit)")
    return name


def rater_of(request: Request, explicit: str | None = None) -> str | None:
    """The request's rater: ``explicit`` (a vote's field), else the ``rater`` query parameter, else the cookie (a
    stale or foreign cookie counts as none)."""
    if explicit is not None:
        return clean_rater(explicit)
    q = request.query_params.get("rater")
    if q is not None:
        return clean_rater(q)
    c = request.cookies.get(COOKIE)
    if c:
        try:
            return clean_rater(unquote(c))
        except HTTPException:
            return None  # a stale or foreign cookie: as if there were none
    return None


def need_rater(request: Request, explicit: str | None = None) -> str:
    r = rater_of(request, explicit)
    if r is None:
        raise HTTPException(400, "no rater: enter your name first (POST /api/rater) or send 'rater'")
    return r


def order_for(study, order_seed: int, rater: str) -> list[str]:
    """The study's pair ids in ``rater``'s own order: shuffled by a seed made of the study's seed and the rater."""
    ids = list(study.pairs)
    h = int(hashlib.sha256(f"{order_seed}:{rater}".encode()).hexdigest()[:16], 16)
    random.Random(h).shuffle(ids)
    return ids


def progress(study, store: VoteStore, rater: str | None) -> dict:
    done = len(store.voted_pairs(rater) & study.pairs.keys()) if rater else 0
    return {"rater": rater, "done": done, "total": len(study.pairs)}


def public_pair(study, pid: str) -> dict:
    """What a rater's page is sent of a pair: its kind, frame rate and media URLs (not which side is which arm)."""
    p = study.pairs[pid]
    return {
        "id": pid,
        "kind": p["kind"],
        "fps": p.get("fps"),
        "left": [f"/media/{pid}/L/{i}" for i in range(len(p["left"]))],
        "right": [f"/media/{pid}/R/{i}" for i in range(len(p["right"]))],
    }


def create_app(study_dir: str | Path, allowed_hosts=None) -> FastAPI:
    """The app of the study in ``study_dir``; ``allowed_hosts``: the ``Host`` headers it answers (``host:port``;
    None: any, until :func:`serve` sets them once its port is bound). Bodies and JSON are guarded (``guard.py``)."""
    study = load_study(study_dir)
    store = VoteStore(Path(study_dir) / "votes.sqlite")
    order_seed = int(study.meta.get("seed", 0))
    app = FastAPI(title="aias-abstudy", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.study, app.state.store = study, store
    app.state.allowed_hosts = None if allowed_hosts is None else frozenset(h.lower() for h in allowed_hosts)
    app.add_middleware(RequestGuard, state=app.state)  # inside the headers middleware: its refusals get them too

    @app.middleware("http")
    async def headers(request: Request, call_next):
        resp = await call_next(request)
        resp.headers["Content-Security-Policy"] = CSP
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Referrer-Policy"] = "no-referrer"
        if request.url.path.startswith("/api/"):
            resp.headers["Cache-Control"] = "no-store"
        return resp

    _add_page_routes(app, study, store)
    _add_rater_routes(app, study, store, order_seed)
    _add_vote_and_media_routes(app, study, store)
    _add_result_routes(app, study, store)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app


def _add_page_routes(app: FastAPI, study, store: VoteStore) -> None:
    @app.get("/", include_in_schema=False)
    def index():
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    @app.get("/results", include_in_schema=False)
    def results_page():
        return FileResponse(STATIC_DIR / "results.html", media_type="text/html")

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon():
        return Response(status_code=204)

    @app.get("/healthz")
    def healthz():
        return {"ok": True, "pairs": len(study.pairs), "votes": store.count()}

    @app.get("/api/study")
    def api_study():
        return {"title": study.meta.get("title"), "kind": study.meta.get("kind"), "pairs": len(study.pairs)}


def _add_rater_routes(app: FastAPI, study, store: VoteStore, order_seed: int) -> None:
    @app.post("/api/rater")
    def api_rater(body: RaterIn):
        rater = clean_rater(body.name)
        if rater is None:
            raise HTTPException(422, "rater id is empty")
        store.add_rater(rater)
        resp = JSONResponse(progress(study, store, rater))
        resp.set_cookie(COOKIE, quote(rater, safe=""), max_age=365 * 24 * 3600, samesite="strict", httponly=True)
        return resp

    @app.get("/api/me")
    def api_me(request: Request):
        return progress(study, store, rater_of(request))

    @app.get("/api/next")
    def api_next(request: Request):
        rater = need_rater(request)
        voted = store.voted_pairs(rater)
        left = [pid for pid in order_for(study, order_seed, rater) if pid not in voted]
        return {**progress(study, store, rater), "pair": public_pair(study, left[0]) if left else None}


def _add_vote_and_media_routes(app: FastAPI, study, store: VoteStore) -> None:
    @app.post("/api/vote", status_code=201)
    def api_vote(body: VoteIn, request: Request):
        rater = need_rater(request, body.rater)
        if not PAIR_ID_RE.match(body.pair_id) or body.pair_id not in study.pairs:
            raise HTTPException(404, f"unknown pair id {body.pair_id[:64]!r}")
        k = study.key[body.pair_id]
        try:
            store.add_vote(rater, body.pair_id, body.choice, k["left"], k["right"], body.ms)
        except DuplicateVote as e:
            return JSONResponse(
                {
                    "detail": f"{rater!r} has already voted on pair {body.pair_id} "
                    f"({e.stored_choice}); one vote per rater and pair",
                    "stored_choice": e.stored_choice,
                },
                status_code=409,
            )
        except (OSError, sqlite3.OperationalError) as e:  # disk full, I/O error, locked past the timeout
            log.error("vote of %r on %s not stored: %s", rater, body.pair_id, e)
            reason = getattr(e, "strerror", None) or str(e)
            return JSONResponse(
                {"detail": f"the server cannot write its vote store ({reason}); try again later", "recorded": False},
                status_code=503,
            )
        return progress(study, store, rater)

    @app.get("/media/{pair_id}/{side}/{index}")
    def media(pair_id: str, side: str, index: str):
        if not PAIR_ID_RE.match(pair_id) or pair_id not in study.pairs:
            raise HTTPException(404, "unknown pair id")
        if side not in ("L", "R") or not INDEX_RE.fullmatch(index):
            raise HTTPException(404, "no such file: side must be L or R and index a frame number")
        path = study.media_path(pair_id, side, int(index))
        if path is None:
            raise HTTPException(404, "no such file")
        return FileResponse(
            path,
            media_type=MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"),
            headers={"Cache-Control": "private, max-age=3600"},
        )


def _add_result_routes(app: FastAPI, study, store: VoteStore) -> None:
    @app.get("/api/results")
    def api_results():
        return compute_report(study, store.votes())

    @app.get("/api/results.csv")
    def api_results_csv():
        return Response(
            results_csv(compute_report(study, store.votes())),
            media_type="text/csv",
            headers={"Content-Disposition": 'attachment; filename="abstudy_results.csv"'},
        )

    @app.get("/api/votes.csv")
    def api_votes_csv():
        return Response(
            votes_csv(study, store.votes()),
            media_type="text/csv",
            headers={"Content-Disposition": 'attachment; filename="abstudy_votes.csv"'},
        )


def serve(study_dir: str | Path, host: str = "127.0.0.1", port: int = 8000, log_level: str = "warning") -> None:
    """Serve until interrupted. The socket is bound first, so ``port=0`` picks a free port; the URL is printed
    (and flushed) as the first line on stdout once the socket is bound."""
    import uvicorn

    app = create_app(study_dir)
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(128)
    bound = sock.getsockname()[1]
    app.state.allowed_hosts = host_names(host, bound)
    shown = f"[{host}]" if ":" in host else host
    print(f"serving {app.state.study.root} on http://{shown}:{bound}/ (results: /results; Ctrl-C stops)", flush=True)
    config = uvicorn.Config(app, log_level=log_level, access_log=False, timeout_graceful_shutdown=5)
    uvicorn.Server(config).run(sockets=[sock])
    sys.stdout.flush()
