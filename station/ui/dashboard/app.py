"""The QA dashboard (``station serve``): a read-only Starlette app over the fleet store.

Pages: the fleet table (sortable and filterable by cell and state, on the server: it works
without script), a robot's history with its SVG plots, a run's figures, and each run's report as
the station wrote it. Assets are the package's own (``static/``); nothing is fetched from the
internet. Every connection is read-only (use the ``fleet_dashboard`` role as well); with a token
or basic auth configured, every request must carry it.
"""

from __future__ import annotations

import base64
import hmac
import queue
import re
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager, contextmanager
from dataclasses import dataclass, fields
from datetime import datetime, timezone
from pathlib import Path
from typing import Any
from urllib.parse import quote

import psycopg
from jinja2 import Environment, FileSystemLoader, select_autoescape
from starlette.applications import Starlette
from starlette.convertors import PathConvertor, register_url_convertor
from starlette.middleware import Middleware
from starlette.middleware.base import BaseHTTPMiddleware, RequestResponseEndpoint
from starlette.requests import Request
from starlette.responses import HTMLResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from station.fleet import store
from station.fleet.overview import STATES, RobotStatus, fleet_status, history_forecast
from station.ui.dashboard.export import rows_csv, rows_json
from station.ui.dashboard.figures import parameter_rows
from station.ui.dashboard.plots import history_svg

__all__ = ["DashboardAuth", "create_app", "SORT_KEYS"]

_HERE = Path(__file__).parent

#: the fleet table's sortable columns: query value -> attribute of RobotStatus
SORT_KEYS = {"robot": "robot_key", "cell": "cell", "station": "station", "calibrated": "last_calibration_utc",
             "gain": "gain", "rms": "rms_after_um", "ap": "ap_max_um", "recheck": "last_recheck_utc",
             "drift": "drift_rms_um", "trend": "drift_trend_um_per_30d", "due": "next_recheck_due_utc",
             "state": "state"}

_PAGE_CSP = "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'none'; frame-ancestors 'none'"
#: the station's report is self-contained HTML (inline styles, data: images): sandboxed, nothing fetched
_REPORT_CSP = "sandbox; default-src 'none'; img-src data:; style-src 'unsafe-inline'; font-src data:"


@dataclass(frozen=True)
class DashboardAuth:
    token: str | None = None  # Authorization: Bearer TOKEN
    basic: tuple[str, str] | None = None  # Authorization: Basic user:password

    @property
    def enabled(self) -> bool:
        return self.token is not None or self.basic is not None

    def allows(self, header: str) -> bool:
        scheme, _, value = header.partition(" ")
        if self.token is not None and scheme.lower() == "bearer":
            return hmac.compare_digest(value.strip().encode(), self.token.encode())
        if self.basic is not None and scheme.lower() == "basic":
            try:
                user, _, password = base64.b64decode(value.strip(), validate=True).decode().partition(":")
            except (ValueError, UnicodeDecodeError):
                return False
            ok_user = hmac.compare_digest(user.encode(), self.basic[0].encode())
            return hmac.compare_digest(password.encode(), self.basic[1].encode()) and ok_user
        return False


class _AuthMiddleware(BaseHTTPMiddleware):
    def __init__(self, app: Any, auth: DashboardAuth) -> None:
        super().__init__(app)
        self.auth = auth

    async def dispatch(self, request: Request, call_next: RequestResponseEndpoint) -> Response:
        if self.auth.enabled and not self.auth.allows(request.headers.get("authorization", "")):
            challenge = 'Basic realm="station QA dashboard"' if self.auth.basic else 'Bearer realm="station"'
            return Response("authentication required\n", status_code=401, headers={"WWW-Authenticate": challenge})
        response = await call_next(request)
        response.headers.setdefault("Content-Security-Policy", _PAGE_CSP)
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        response.headers.setdefault("Cache-Control", "no-store")
        return response


class _Pool:
    """A few read-only connections, reused; a broken one is dropped and replaced."""

    def __init__(self, url: str, size: int = 4) -> None:
        self.url, self._free = url, queue.LifoQueue[psycopg.Connection](maxsize=size)
        self._lock = threading.Lock()

    @contextmanager
    def connection(self) -> Iterator[psycopg.Connection]:
        try:
            conn = self._free.get_nowait()
        except queue.Empty:
            conn = store.connect(self.url, read_only=True, autocommit=True)
        try:
            yield conn
        except BaseException:
            conn.close()
            raise
        if conn.broken or conn.closed:
            return
        try:
            self._free.put_nowait(conn)
        except queue.Full:
            conn.close()

    def close(self) -> None:
        while True:
            try:
                self._free.get_nowait().close()
            except queue.Empty:
                return


def _fmt(v: Any, digits: int = 1) -> str:
    if v is None:
        return "—"
    if isinstance(v, (int, float)) and not isinstance(v, bool):  # jsonb gives 11.0 back as 11
        return f"{v:.{digits}f}"
    return str(v)


def _date(v: Any) -> str:
    if v is None:
        return "—"
    if isinstance(v, datetime):
        return v.astimezone(timezone.utc).strftime("%Y-%m-%d %H:%M")
    return str(v)[:16].replace("T", " ")


def _download(request: Request, name: str, rows: list[dict[str, Any]], columns: list[str], **about: Any) -> Response:
    """The rows as the file the path's suffix names, with its units (export.py)."""
    if request.url.path.endswith(".json"):
        body, media = rows_json(rows, columns, **about), "application/json"
    else:
        body, media = rows_csv(rows, columns), "text/csv; charset=utf-8"
    suffix = request.url.path.rsplit(".", 1)[-1]
    return Response(body, media_type=media,
                    headers={"Content-Disposition": f'attachment; filename="{name}.{suffix}"'})


def _certificate(detail: dict[str, Any], key: str) -> tuple[str, str]:
    """A stored certificate's id and date; ('—', '') where the detail holds no object under ``key``
    (a station may store a list or a string there: the page said 500, issue 39's property test)."""
    cert = detail.get(key)
    if not isinstance(cert, dict):
        return "—", ""
    return str(cert.get("id") or "—"), str(cert.get("date") or "")


class _RobotKey(PathConvertor):
    """A robot key in a path: any text, line breaks included (the path convertor's '.*' stops at
    one: a key a station stored as "line\nbreak" linked to a 404, issue 39's property test)."""

    regex = r"[\s\S]*"


register_url_convertor("robot_key", _RobotKey())


def path_segment(key: str) -> str:
    """A robot key as one path segment: every reserved character encoded, '/' and '.' included
    (Jinja's urlencode leaves '/' as is: a serial 'a/../b' linked to a page the browser rewrote
    to /robots/b). The route takes the key with its '/' decoded ({key:robot_key})."""
    return quote(str(key), safe="")


class _Pages:
    """The dashboard's pages over one store, each a Starlette endpoint: the fleet, a robot, a run,
    its report and certificate, and the exports (``clock``: when states and due dates are
    reckoned)."""

    def __init__(self, url: str, interval_days: int, clock: Callable[[], datetime] | None) -> None:
        self.env = Environment(loader=FileSystemLoader(str(_HERE / "templates")),
                               autoescape=select_autoescape(["html"]))
        self.env.filters["fmt"] = _fmt
        self.env.filters["date"] = _date
        self.env.filters["segment"] = path_segment
        self.pool = _Pool(url)
        self.interval_days = interval_days
        self.clock = clock

    def render(self, name: str, status: int = 200, **ctx: Any) -> HTMLResponse:
        started = ctx.pop("_started", None)
        html = self.env.get_template(name).render(**ctx)
        headers = {} if started is None else {"Server-Timing": f"app;dur={(time.perf_counter() - started) * 1e3:.1f}"}
        return HTMLResponse(html, status_code=status, headers=headers)

    def fleet_rows(self, request: Request) -> tuple[list[Any], list[Any], str, str, str, bool]:
        """All robots, and those the query's cell and state show in its sort order."""
        q = request.query_params
        with self.pool.connection() as conn:
            robots = fleet_status(conn, self.clock() if self.clock else None, default_interval_days=self.interval_days)
        cell, state = q.get("cell", ""), q.get("state", "")
        shown = [r for r in robots if (not cell or r.cell == cell) and (not state or r.state == state)]
        sort = q.get("sort", "robot") if q.get("sort", "robot") in SORT_KEYS else "robot"
        desc = q.get("order") == "desc"
        attr = SORT_KEYS[sort]
        present = [r for r in shown if getattr(r, attr) is not None]
        missing = [r for r in shown if getattr(r, attr) is None]
        present.sort(key=lambda r: getattr(r, attr), reverse=desc)
        return robots, present + missing, cell, state, sort, desc

    def fleet_page(self, request: Request) -> Response:
        started = time.perf_counter()
        robots, shown, cell, state, sort, desc = self.fleet_rows(request)
        counts = {s: sum(1 for r in robots if r.state == s) for s in STATES}
        return self.render("fleet.html", robots=shown, cells=sorted({r.cell for r in robots}), states=STATES, cell=cell,
                      state=state, sort=sort, desc=desc, counts=counts, total=len(robots),
                      query=request.url.query, _started=started)

    def fleet_export(self, request: Request) -> Response:
        """/fleet.csv, /fleet.json: the table as shown (the same cell, state and sort)."""
        _, shown, cell, state, _, _ = self.fleet_rows(request)
        rows = [r.to_json() for r in shown]
        columns = [f.name for f in fields(RobotStatus)] + ["overdue"]
        return _download(request, "fleet", rows, columns, what="the fleet table", cell=cell or None,
                         state=state or None)

    def history_export(self, request: Request) -> Response:
        """/history.csv?robot=KEY, /history.json?robot=KEY: a robot's runs, oldest first."""
        key = request.query_params.get("robot")
        if key is None or "\x00" in key:  # "" is a key a station may store (the robot page links robot=)
            return self.render("missing.html", 404, what=f"robot {key!r}")
        with self.pool.connection() as conn:
            runs = store.robot_history(conn, key)
        if not runs:
            return self.render("missing.html", 404, what=f"robot {key}")
        return _download(request, "history", runs, list(runs[0]), what="a robot's runs, oldest first", robot=key)

    def robot_page(self, request: Request) -> Response:
        started = time.perf_counter()
        key = request.path_params["key"]
        # a NUL: no stored key has one (no PostgreSQL text holds it; the driver refused the query: 503).
        # Other control characters are a stored key's own: a station may write "\x1b[31m" (issue 39)
        if "\x00" in key:
            return self.render("missing.html", 404, what=f"robot {key!r}")
        with self.pool.connection() as conn:
            runs = store.robot_history(conn, key)
        if not runs:
            return self.render("missing.html", 404, what=f"robot {key}")
        # the plots show the robot's own history: neither rehearsals nor rows without a readable date
        accuracy, drift = history_svg([r for r in runs if not r.get("simulated") and r.get("finished_utc")])
        return self.render("robot.html", key=key, runs=list(reversed(runs)), latest=runs[-1], accuracy_svg=accuracy,
                      forecast=history_forecast(runs),
                      drift_svg=drift, n_cal=sum(r["kind"] == "calibration" for r in runs),
                      n_rec=sum(r["kind"] == "recheck" for r in runs), n_sim=sum(bool(r.get("simulated")) for r in runs),
                      _started=started)

    def run_page(self, request: Request) -> Response:
        uid = request.path_params["uuid"]
        with self.pool.connection() as conn:
            run = store.run_detail(conn, str(uid))
            has_report = run is not None and store.report_html(conn, str(uid)) is not None
            has_certificate = run is not None and store.certificate_xml(conn, str(uid)) is not None
        if run is None:
            return self.render("missing.html", 404, what=f"run {uid}")
        stored = run.get("detail")
        detail: dict[str, Any] = stored if isinstance(stored, dict) else {}  # a stored list: no 500
        ident = detail.get("identification")
        ident = ident if isinstance(ident, dict) else {}
        params, params_note = parameter_rows(detail)
        return self.render("run.html", run={**run, "detail": detail}, params=params, params_note=params_note,
                      has_report=has_report, has_certificate=has_certificate,
                      has_covariance=bool(ident.get("covariance")),
                      head_cert=_certificate(detail, "head_certificate"),
                      body_cert=_certificate(detail, "body_certificate"))

    def report_page(self, request: Request) -> Response:
        uid = request.path_params["uuid"]
        with self.pool.connection() as conn:
            html = store.report_html(conn, str(uid))
        if html is None:
            return self.render("missing.html", 404, what=f"a report of run {uid}")
        return HTMLResponse(html, headers={"Content-Security-Policy": _REPORT_CSP})

    def certificate(self, request: Request) -> Response:
        """The run's Digital Calibration Certificate: the bytes 'station export-dcc' wrote (issue 41)."""
        uid = request.path_params["uuid"]
        with self.pool.connection() as conn:
            run = store.run_detail(conn, str(uid))
            xml = store.certificate_xml(conn, str(uid)) if run is not None else None
        if run is None or xml is None:
            return self.render("missing.html", 404, what=f"a calibration certificate of run {uid}")
        name = re.sub(r"[^A-Za-z0-9._-]", "_", f"certificate-{run['robot_key']}-run-{run['local_run_id']}.xml")
        return Response(xml, media_type="application/xml",
                        headers={"Content-Disposition": f'attachment; filename="{name}"'})


def create_app(url: str, *, auth: DashboardAuth | None = None, interval_days: int = 30,
               clock: Callable[[], datetime] | None = None) -> Starlette:
    """The app over the store at ``url``; ``clock``: the time the states and due dates are
    reckoned at (default now; tests pass a fixed one)."""
    pages = _Pages(url, interval_days, clock)
    routes = [
        Route("/", pages.fleet_page),
        Route("/fleet.csv", pages.fleet_export), Route("/fleet.json", pages.fleet_export),
        Route("/history.csv", pages.history_export), Route("/history.json", pages.history_export),
        Route("/robots/{key:robot_key}", pages.robot_page),
        Route("/runs/{uuid:uuid}", pages.run_page),
        Route("/runs/{uuid:uuid}/report", pages.report_page),
        Route("/runs/{uuid:uuid}/certificate.xml", pages.certificate),
        Mount("/static", app=StaticFiles(directory=str(_HERE / "static")), name="static"),
    ]
    middleware = [Middleware(_AuthMiddleware, auth=auth or DashboardAuth())]

    @asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        yield
        pages.pool.close()

    async def unavailable(request: Request, exc: Exception) -> Response:
        """The store is down or refused: a page that says so (503), never a traceback."""
        what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        html = pages.env.get_template("missing.html").render(what=f"answer now: the fleet store is unavailable ({what})")
        return HTMLResponse(html, status_code=503)

    handlers: dict[Any, Any] = {psycopg.Error: unavailable, store.FleetStoreError: unavailable}
    return Starlette(routes=routes, middleware=middleware, lifespan=lifespan, exception_handlers=handlers)
