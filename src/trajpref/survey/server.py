"""``trajpref survey serve``: the rating page (Starlette on uvicorn), answers in SQLite.

Routes::

    GET  /                                       the page (static/index.html)
    GET  /static/{app.js,style.css}              its script and style (package data)
    GET  /images/{name}.png                      a panel image named in the manifest
    GET  /api/study                              the public study: scenes, panels, criteria,
                                                 the consent text and its ``consent_hash``
    GET  /api/raters/{rater}                     a rater's answers so far (to resume) and the
                                                 order the rater sees the pictures in
    PUT  /api/raters/{rater}/answers/{scene}/{panel}   {"social": 1..5, "kinetics": 1..5}
    POST /api/raters/{rater}/submit              {"submit": true}: mark the answers final
                                                 (every panel answered, else 409)
    POST /api/raters/{rater}/consent             {"agree": true, "text_hash": consent_hash}:
                                                 agree to the study's consent text (a study
                                                 with one refuses answers before: 403; a
                                                 hash of another text: 409)

Security: binds to 127.0.0.1 unless told otherwise, and then refuses requests whose Host
header is not a loopback name (DNS rebinding); serves only the files named in the manifest
and the three static files (a fixed table: no path from a request ever reaches the file
system); reads at most ``max_body`` bytes of a body (413 beyond); takes JSON only
(``Content-Type: application/json``, so a cross-site form cannot post answers, an agreement
to the consent text or a submission: 415); refuses a change (PUT answers, POST consent or
submit) whose ``Origin`` header names another host than its ``Host`` header (403); sends a
strict Content-Security-Policy. Errors are JSON ``{"error": message}`` with a 4xx status,
or 503 when the database failed (``StoreError``: a disk error, the study folder deleted while
serving), which is also logged in one line. The access log shows ``/api/raters/<id>/...`` in
place of the rater id (personal data: ``RaterIdMask``).

Stopping: Ctrl-C (SIGINT) and SIGTERM alike let the requests in progress finish, then close
the answers database in uvicorn's shutdown (the app's lifespan), so that the file alone holds
every answer (``AnswerStore.close``) even though uvicorn re-raises a SIGTERM once it has shut
down, which ends the process before ``serve`` could close anything itself.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Iterator
from importlib import resources
from pathlib import Path
from typing import Any

import uvicorn
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import MutableHeaders
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from trajpref.errors import ConfigError
from trajpref.survey.manifest import DATABASE, Study, load_study
from trajpref.survey.store import (
    AnswerError,
    AnswerStore,
    StoreError,
    check_agreement,
    check_rater,
)

MAX_BODY = 4096
"""Default limit of a request body in bytes (an answer is about 30)."""
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
"""Host names accepted in the Host header when the server listens on loopback."""
STATIC = {
    "app.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
}
"""The static files besides index.html, with their types."""
CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
"""Content-Security-Policy of every response."""
LOG = logging.getLogger("uvicorn.error")
"""Where a failed write is logged (uvicorn's own log: on stderr, also with ``--quiet``)."""


RATER_PATH_RE = re.compile(r"(/api/raters/)[^/?#\s]*", re.IGNORECASE)
"""The rater id in a request path (the API's ``/api/raters/{rater}...``)."""


def mask_rater_ids(text: str) -> str:
    """``text`` with every rater id of an API path replaced by ``<id>``
    (``GET /api/raters/alice@example.org/submit`` -> ``GET /api/raters/<id>/submit``)."""
    return RATER_PATH_RE.sub(r"\1<id>", text)


class RaterIdMask(logging.Filter):
    """A logging filter that masks rater ids (personal data: often a name or an e-mail
    address) in the arguments and message of a record: ``serve`` puts it on uvicorn's access
    log, which would otherwise print every request path."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(mask_rater_ids(a) if isinstance(a, str) else a
                                for a in record.args)  # fmt: skip
        if isinstance(record.msg, str):
            record.msg = mask_rater_ids(record.msg)
        return True


def mask_access_log() -> None:
    """Put ``RaterIdMask`` on uvicorn's access logger (once)."""
    logger = logging.getLogger("uvicorn.access")
    if not any(isinstance(f, RaterIdMask) for f in logger.filters):
        logger.addFilter(RaterIdMask())


def _static_bytes(name: str) -> bytes:
    return (resources.files("trajpref.survey") / "static" / name).read_bytes()


def is_loopback(host: str) -> bool:
    return host in LOOPBACK_NAMES or host.startswith("127.")


def _host_name(header: str) -> str:
    """The host of a Host header, without the port (``[::1]:8000`` -> ``::1``)."""
    if header.startswith("["):
        return header[1 : header.find("]")] if "]" in header else header
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


class _Guard:
    """ASGI middleware: security headers on every response, and the Host check."""

    def __init__(self, app, allowed_hosts: tuple[str, ...] | None):
        self.app = app
        self.allowed_hosts = allowed_hosts

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def send_headers(message):
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                headers["Content-Security-Policy"] = CSP
                headers["X-Content-Type-Options"] = "nosniff"
                headers["Referrer-Policy"] = "no-referrer"
                headers["Cache-Control"] = headers.get("Cache-Control", "no-store")
            await send(message)

        if self.allowed_hosts is not None:
            host = dict(scope.get("headers", [])).get(b"host", b"").decode("latin-1")
            if _host_name(host) not in self.allowed_hosts:
                response = JSONResponse({"error": f"unexpected Host header {host!r:.60}"}, 400)
                return await response(scope, receive, send_headers)
        return await self.app(scope, receive, send_headers)


def _error(message: str, status: int) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


def _refused(exc: AnswerError) -> JSONResponse:
    """The JSON error of an ``AnswerError``; a ``StoreError`` (the database failed: 503) is
    also logged, in one line that names the database and not the rater."""
    if isinstance(exc, StoreError):
        LOG.error(exc.log)
    return _error(str(exc), exc.status)


async def _read_json(request: Request, limit: int) -> Any:
    """The body as JSON, at most ``limit`` bytes; AnswerError (400/413/415) otherwise."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype != "application/json":
        raise AnswerError("send the body as JSON (Content-Type: application/json)", 415)
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > limit):
        raise AnswerError(f"the body is limited to {limit} bytes", 413)
    body = bytearray()
    async for chunk in request.stream():
        body += chunk
        if len(body) > limit:
            raise AnswerError(f"the body is limited to {limit} bytes", 413)
    try:
        return json.loads(body.decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError):  # nested past Python's limit
        raise AnswerError("the body is not valid JSON", 400) from None


def _check_origin(request: Request) -> None:
    """AnswerError 403 for a request whose ``Origin`` header (a browser sends it with every
    PUT and POST) is there and names another host (and port) than the ``Host`` header: a
    request made by a page of another site. No ``Origin`` (curl, scripts) passes."""
    origin = request.headers.get("origin")
    if origin is None:
        return
    host = request.headers.get("host", "").lower()
    scheme, sep, netloc = origin.lower().partition("://")
    default = DEFAULT_PORTS.get(scheme)  # a proxy may name it in Host, a browser never in Origin
    if default and host.endswith(default):
        host = host[: -len(default)]
    if not sep or not host or netloc != host:
        raise AnswerError(f"request from another origin ({origin!r:.60}) refused", 403)


DEFAULT_PORTS = {"http": ":80", "https": ":443"}
"""The port a ``Host`` header may name that an ``Origin`` of that scheme leaves out."""


def check_submission(body: Any) -> None:
    """``{"submit": true}`` (the body of ``POST .../submit``, nothing else); AnswerError 422
    otherwise."""
    if not isinstance(body, dict) or set(body) != {"submit"} or body["submit"] is not True:
        raise AnswerError('the body of a submission must be the JSON object {"submit": true}',
                          422)  # fmt: skip


def create_app(study: Study, store: AnswerStore, max_body: int = MAX_BODY,
               allowed_hosts: tuple[str, ...] | None = None,
               close_store: bool = False) -> Starlette:  # fmt: skip
    """The web application of one study. ``allowed_hosts`` (e.g. ``LOOPBACK_NAMES``) turns
    the Host check on. ``close_store``: the app's lifespan closes ``store`` when the server
    shuts down (``serve``: after SIGTERM as after Ctrl-C)."""
    if max_body < 64:
        raise ConfigError("--max-body must be >= 64 bytes")
    public = {**study.public(), "consent_hash": study.consent_hash if study.consent else None}
    images = study.image_files()  # the only files served from the study folder
    static = {name: (_static_bytes(name), kind) for name, kind in STATIC.items()}
    index = _static_bytes("index.html")

    async def _in_thread(failed: str, action, *args) -> Any:
        """``action(*args)`` in the thread pool; an SQLite error that the store did not turn
        into a ``StoreError`` becomes one (``failed``: "the answer was not saved"), so that
        the rater gets JSON, never a plain-text 500."""
        try:
            return await run_in_threadpool(action, *args)
        except sqlite3.Error as exc:
            raise StoreError(f"{failed}: {exc}", f"{store.path}: {failed}: {exc}") from exc

    async def page(request: Request) -> Response:
        return Response(index, media_type="text/html; charset=utf-8",
                        headers={"Cache-Control": "no-cache"})  # fmt: skip

    async def static_file(request: Request) -> Response:
        item = static.get(request.path_params["name"])
        if item is None:
            return _error("not found", 404)
        return Response(item[0], media_type=item[1], headers={"Cache-Control": "no-cache"})

    async def image(request: Request) -> Response:
        path = images.get(request.path_params["name"])
        if path is None or not path.is_file():
            return _error("not found", 404)
        return FileResponse(path, media_type="image/png",
                            headers={"Cache-Control": "private, max-age=3600"})  # fmt: skip

    async def study_info(request: Request) -> Response:
        return JSONResponse(public)

    def per_rater(action, failed: str):
        """An endpoint that runs ``action(rater)`` on the store for a checked rater id."""

        async def endpoint(request: Request) -> Response:
            try:
                rater = check_rater(request.path_params["rater"])
                return JSONResponse(await _in_thread(failed, action, rater))
            except AnswerError as exc:
                return _refused(exc)

        return endpoint

    rater_info = per_rater(store.progress, "the answers could not be read")

    async def answer(request: Request) -> Response:
        p = request.path_params
        try:
            check_rater(p["rater"])
            store.check_panel(p["scene"], p["panel"])
            ratings = await _read_json(request, max_body)
            _check_origin(request)
            saved = await _in_thread("the answer was not saved", store.save, p["rater"],
                                     p["scene"], p["panel"], ratings)  # fmt: skip
        except AnswerError as exc:
            return _refused(exc)
        return JSONResponse({"saved": True, **saved})

    async def submit(request: Request) -> Response:
        """Mark the rater's answers final: JSON ``{"submit": true}`` only (a cross-site form
        cannot send it)."""
        try:
            rater = check_rater(request.path_params["rater"])
            body = await _read_json(request, max_body)
            _check_origin(request)
            check_submission(body)
            done = await _in_thread("the submission was not saved", store.submit, rater)
        except AnswerError as exc:
            return _refused(exc)
        return JSONResponse(done)

    async def consent(request: Request) -> Response:
        """The rater's agreement: JSON only (a cross-site form cannot send it), naming the
        text the page showed."""
        try:
            rater = check_rater(request.path_params["rater"])
            body = await _read_json(request, max_body)
            _check_origin(request)
            text_hash = check_agreement(body)
            agreed = await _in_thread("the agreement was not saved", store.consent, rater,
                                      text_hash)  # fmt: skip
        except AnswerError as exc:
            return _refused(exc)
        return JSONResponse(agreed)

    async def http_error(request: Request, exc: HTTPException) -> Response:
        return _error(exc.detail, exc.status_code)

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        yield
        if close_store:  # the requests in progress have finished: uvicorn waited for them
            await run_in_threadpool(store.close)

    app = Starlette(
        routes=[
            Route("/", page, methods=["GET"]),
            Route("/static/{name}", static_file, methods=["GET"]),
            Route("/images/{name}", image, methods=["GET"]),
            Route("/api/study", study_info, methods=["GET"]),
            Route("/api/raters/{rater}", rater_info, methods=["GET"]),
            Route("/api/raters/{rater}/answers/{scene}/{panel}", answer, methods=["PUT"]),
            Route("/api/raters/{rater}/submit", submit, methods=["POST"]),
            Route("/api/raters/{rater}/consent", consent, methods=["POST"]),
        ],
        exception_handlers={HTTPException: http_error},
        lifespan=lifespan,
    )
    return _Guard(app, allowed_hosts)  # type: ignore[return-value]


def bind(host: str, port: int) -> socket.socket:
    """A listening socket, or a one-line ConfigError (port taken, unknown host)."""
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.create_server((host, port), family=family, backlog=2048)
    except (OSError, OverflowError) as exc:
        raise ConfigError(f"cannot listen on {host}:{port}: {exc}") from None
    sock.setblocking(False)
    return sock


def url_of(sock: socket.socket) -> str:
    host, port = sock.getsockname()[:2]
    return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"


def open_study(folder: str | Path, db: str | Path | None = None) -> tuple[Study, AnswerStore]:
    """Check the study folder first; only then open (or create) its answers database."""
    study = load_study(folder)
    return study, AnswerStore(db or study.folder / DATABASE, study)


def serve(
    folder: str | Path,
    host: str = "127.0.0.1",
    port: int = 8000,
    db: str | Path | None = None,
    max_body: int = MAX_BODY,
    quiet: bool = False,
) -> None:
    """Serve a study until interrupted; prints its address once listening. Everything a user
    can get wrong (the folder, the manifest, the port, the database) is checked first, in
    that order, and ends in a ConfigError or DataError before anything is written."""
    if max_body < 64:
        raise ConfigError("--max-body must be >= 64 bytes")
    study = load_study(folder)
    sock = bind(host, port)
    try:
        store = AnswerStore(db or study.folder / DATABASE, study)
        try:
            allowed = (*LOOPBACK_NAMES, host) if is_loopback(host) else None
            app = create_app(study, store, max_body, allowed, close_store=True)
            config = uvicorn.Config(app, log_level="warning" if quiet else "info",
                                    access_log=not quiet, server_header=False)  # fmt: skip
            mask_access_log()  # after the Config: it sets uvicorn's loggers up
            note = "" if is_loopback(host) else " (not loopback: anyone who can reach it may rate)"
            print(f"serving {study.title!r}: {len(study.scenes)} scenes, {study.num_panels} "
                  f"panels at {url_of(sock)}{note}; answers in {store.path}; Ctrl-C (or "
                  "SIGTERM) to stop",
                  flush=True)  # fmt: skip
            uvicorn.Server(config).run(sockets=[sock])
        finally:
            store.close()  # closed already after a clean shutdown; not after a second Ctrl-C
    finally:
        sock.close()


class ServerThread:
    """The app on a free loopback port in a background thread (tests, benchmarks)::

    with ServerThread(study, store) as url: ...
    """

    def __init__(self, study: Study, store: AnswerStore, max_body: int = MAX_BODY):
        self.sock = bind("127.0.0.1", 0)
        self.url = url_of(self.sock)
        app = create_app(study, store, max_body, LOOPBACK_NAMES)
        config = uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]},
                                       daemon=True)  # fmt: skip

    def __enter__(self) -> str:
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the survey server did not start")
            time.sleep(0.02)
        return self.url

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.sock.close()


@contextlib.contextmanager
def running(folder: str | Path, db: str | Path | None = None) -> Iterator[tuple[str, AnswerStore]]:
    """Open a study and serve it in a background thread: ``(url, store)``."""
    study, store = open_study(folder, db)
    try:
        with ServerThread(study, store) as url:
            yield url, store
    finally:
        store.close()


def serve_subprocess(folder: str | Path) -> tuple[subprocess.Popen, str]:
    """``trajpref survey serve FOLDER`` in a child process on a free loopback port (the real
    command, for durability tests and load tests): ``(process, url)`` once it listens. The
    caller stops the process and closes its pipes."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "trajpref.cli", "survey", "serve", str(folder), "--port", "0",
         "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    line = proc.stdout.readline()  # "serving ... at URL; answers in ..."
    if "serving" not in line:
        proc.kill()
        message = proc.stderr.read().strip()
        proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()
        raise ConfigError(f"the survey server did not start: {message}")
    return proc, line.split(" at ")[1].split(";")[0].strip()
