"""The studio's web server: a Starlette app over one :class:`Studio` session, served by uvicorn
on 127.0.0.1 only.

Security. Every request must name the host it was sent to as ``127.0.0.1:PORT`` or
``localhost:PORT`` (a DNS-rebinding page cannot), and a request that carries an ``Origin`` must
come from that same origin (no other web page can drive the studio). The page and every
``/api`` or ``/ws`` request also need the session's random token, as ``?token=`` or the
``X-Tagbot-Token`` header; it is in the URL the studio prints and opens. Refusals are
``403`` with ``{"error": "..."}``.

The JSON API (what the page itself uses; bodies are JSON, answers JSON unless said otherwise,
errors ``4xx`` with ``{"error": "<field>: <problem>"}``):

- ``GET /api/state``: the design, its tag (plan-file object or null), the sampled trajectory
  (``motion``: ``t, x, y, speed, pen``), per stroke its lognormal and handle directions
  (``strokes``), ``version``, ``can_undo``/``can_redo``, the draw status and settings.
- ``GET /api/plan``: the tag as a tagbot-plan file (``?download=1``: as an attachment, the
  same bytes ``tagbot fit -o`` writes); ``PUT /api/plan``: replace the design by a plan file.
- ``PATCH /api/plan``: ``{"ops": [...], "group": "drag-1"}``, edits applied in order, all or
  none (:mod:`tagbot.studio.design`): ``move_target {plan, index, to}``, ``move_plan {plan,
  by}``, ``aim {plan, stroke, end: 1|2, toward}`` (point a φ handle), ``set {plan, stroke,
  field, value}`` (``dt, mu, sigma, phi1, phi2, phi``), ``dt_fraction {plan, stroke,
  fraction}`` (a Δt handle: Δt_min + fraction·(Δt_max − Δt_min)), ``insert {plan, index, at}``,
  ``append {plan, at}``, ``delete {plan, index}``, ``new_plan {at}``, ``delete_plan {plan}``,
  ``lift {plan, seconds}``, ``globals {dt_min, dt_max, mu, sigma, lift}``, ``model {model}``,
  ``clear {}``. Edits with the same ``group`` as the previous request make one undo step.
- ``POST /api/undo``, ``POST /api/redo``.
- ``POST /api/gesture``: ``{"points": [[x, y, t], ...]}`` (tag units, seconds): fitted at once
  with :func:`tagbot.fit` into a new plan (the design's model and Δt range); answers the state
  and ``fit_ms``.
- ``POST /api/open?name=FILE``: the body is a file's bytes: a plan file, or any input tagbot
  reads (GML, SVG, points), fitted.
- ``POST /api/save``: write the plan file the studio was started with.
- ``POST /api/variations`` ``{"count": n, "seed": s}``: §7 variations (:func:`tagbot.vary`),
  each with its trajectory; ``POST /api/variations/adopt`` ``{"index": i}``.
- ``GET /api/brush.png?width=&height=&drips=&seed=``: the brush preview
  (:func:`tagbot.render.render_array`).
- ``GET /api/export?format=png|svg|gif|gcode|json``: the file ``tagbot render``, ``tagbot
  gcode`` or ``tagbot fit`` writes (``&drips=1&seed=N`` for pictures).
- ``POST /api/draw`` ``{"device": "grbl"|"dynamixel"|"axidraw", "profile": …}``: draw on the
  simulator, or on the port named with ``tagbot studio --machine-port``; the run folder is
  ``tagbot draw``'s. With ``"device": "dynamixel"``, ``"profile"`` picks a serial arm
  (:data:`SERIAL_ARMS`: ``openmanipulator-x``, ``koch-v1.1``; simulated with its physics) instead
  of the planar arm.
  ``POST /api/draw/pause``, ``/resume``, ``/stop``; ``GET /api/draw``: its status.
- ``GET /ws``: a WebSocket. The server sends events: ``{"type": "draw", "state", "done",
  "total", "points": [[x, y, pen], ...]}`` while a draw runs (points in tag units, as
  executed), and its end with the executed trace and the report's summary. The client may send
  edits, ``{"id": n, "ops": [...], "group": ...}`` exactly as for ``PATCH /api/plan``, answered
  in order by ``{"type": "state", "id": n, "state": {...}}`` or ``{"type": "error", "id": n,
  "error": "..."}`` (the page drags this way: no HTTP request per pointer move).

Arrays in the state (``motion``'s ``x, y, speed, pen``, sample ``i`` at ``t0 + i·dt``;
``strokes``' ``t, v``) are packed, ``{"dtype": "<f4", "b64": ...}`` (little-endian bytes in
base64); ``?arrays=json`` on any request answering the state gives plain JSON lists instead
(and ``motion.t``).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import inspect
import io
import json
import logging
import math
import os
import secrets
import socket
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from tagbot.control import RunControl
from tagbot.errors import Interrupted, TagbotError
from tagbot.io.planfile import plan_bytes
from tagbot.model.plan import Tag
from tagbot.studio.design import (
    Design,
    History,
    StudioError,
    apply,
    apply_ops,
    design_from_tag,
    empty_design,
    integer,
    motion_view,
    number,
    tag_of,
    view,
)

__all__ = ["MAX_BODY", "Studio", "StudioServer", "create_app"]

log = logging.getLogger(__name__)

MAX_BODY = 2 * 1024 * 1024
"""Largest JSON request body, bytes."""
MAX_GESTURE_POINTS = 20_000
"""Points in one gesture."""
MAX_VARIANTS = 12
"""Variations shown at once."""
MAX_PICTURE = 4000
"""Largest brush preview side, pixels."""
EVENT_INTERVAL = 0.04
"""Seconds between draw progress events at most (25 a second)."""
DEVICES = ("grbl", "dynamixel", "axidraw")
"""The machines the Draw button offers (``tagbot draw --device``)."""
SERIAL_ARMS = ("openmanipulator-x", "koch-v1.1")
"""The serial arms the Draw button offers (``tagbot draw --device dynamixel --profile``)."""
STATIC = Path(__file__).with_name("static")
AUTOSAVE_FORMAT = "tagbot-studio"

_CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".png": "image/png",
    ".svg": "image/svg+xml",
}


class HTTPError(Exception):
    """An answer with a status and a one-line message."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def default_autosave() -> Path:
    """``$XDG_STATE_HOME/tagbot/studio.json`` (``~/.local/state/tagbot/studio.json``)."""
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(Path.home(), ".local", "state")
    return Path(base) / "tagbot" / "studio.json"


class StopControl(RunControl):
    """A :class:`RunControl` that can also stop the run: the back end's next look at
    :attr:`paused` (each stream loop, each arm tick) raises KeyboardInterrupt once, which every
    back end turns into a safe stop, as for Ctrl-C."""

    def __init__(self) -> None:
        super().__init__()
        self._stop = threading.Event()
        self._raised = False
        self._lock = threading.Lock()

    def stop(self) -> None:
        self._stop.set()
        self.resume()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def check(self) -> None:
        """Raise KeyboardInterrupt once after :meth:`stop`."""
        with self._lock:
            if self._stop.is_set() and not self._raised:
                self._raised = True
                raise KeyboardInterrupt

    @property
    def paused(self) -> bool:
        self.check()
        return super().paused


@dataclass
class DrawState:
    """What the page is told about the current (or last) draw."""

    state: str = "idle"
    device: str | None = None
    port: str | None = None
    folder: str | None = None
    profile: str | None = None
    """A serial arm's profile (None: the device's default machine)."""
    done: int = 0
    total: int = 0
    error: str | None = None
    summary: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "state": self.state,
            "device": self.device,
            "profile": self.profile,
            "port": self.port,
            "folder": self.folder,
            "done": self.done,
            "total": self.total,
            "error": self.error,
            "summary": self.summary,
        }


class Studio:
    """One studio session: the design and its history, autosave, variations, and draws."""

    def __init__(
        self,
        *,
        tag: Tag | None = None,
        gestures: list[list[list[float]]] | None = None,
        autosave: Path | None = None,
        runs: Path = Path("runs"),
        machine_port: str | None = None,
        plan_path: Path | None = None,
        name: str = "studio",
        token: str | None = None,
    ) -> None:
        self.token = token or secrets.token_urlsafe(24)
        self.autosave = autosave
        self.runs = runs
        self.machine_port = machine_port
        self.plan_path = plan_path
        self.name = name
        design = empty_design()
        if tag is not None:
            design = design_from_tag(tag, design)
            design["gestures"] = gestures or []
        elif autosave is not None:
            design = _read_autosave(autosave) or design
        self.history = History(design)
        self._built: tuple[Design | None, Tag | None] = (None, None)
        self.variants: list[Tag] = []
        self.draw = DrawState()
        self.control: StopControl | None = None
        self.clients: set[WebSocket] = set()
        self.loop: asyncio.AbstractEventLoop | None = None
        self.ready = threading.Event()
        self._autosave_handle: asyncio.TimerHandle | None = None
        # One worker each, started at once (a lazily started thread would look leaked).
        self.compute = _started_executor("tagbot-studio-compute")
        self.machine = _started_executor("tagbot-studio-draw")

    # -- state ------------------------------------------------------------------------------

    @property
    def design(self) -> Design:
        return self.history.design

    def state(self, arrays: str = "packed") -> dict[str, Any]:
        """``GET /api/state`` (``arrays="json"``: plain lists instead of packed arrays)."""
        design, tag = self._built
        result = view(self.design, tag if design is self.design else None, arrays)
        result |= {
            "version": self.history.version,
            "can_undo": bool(self.history.undo_stack),
            "can_redo": bool(self.history.redo_stack),
            "draw": self.draw.as_dict(),
            "machine_port": self.machine_port,
            "save_path": str(self.plan_path) if self.plan_path else None,
            "name": self.name,
            "ready": self.ready.is_set(),
        }
        return result

    def commit(self, design: Design, group: str | None = None, tag: Tag | None = None) -> None:
        """Make ``design`` current (``tag``: its tag, if already built)."""
        self.history.commit(design, group)
        if tag is not None:
            self._built = (design, tag)
        self.schedule_autosave()

    def schedule_autosave(self) -> None:
        if self.autosave is None or self.loop is None:
            return
        if self._autosave_handle is not None:
            self._autosave_handle.cancel()
        self._autosave_handle = self.loop.call_later(0.3, self.save_autosave)

    def save_autosave(self) -> None:
        """Write the design (atomically) to the autosave file; failures are logged, not raised."""
        self._autosave_handle = None
        if self.autosave is None:
            return
        data = {"format": AUTOSAVE_FORMAT, "version": 1, "design": self.design}
        try:
            self.autosave.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.autosave.with_name(f".{self.autosave.name}.{secrets.token_hex(4)}.tmp")
            tmp.write_text(json.dumps(data), encoding="utf-8")
            os.replace(tmp, self.autosave)
        except OSError as e:
            log.warning("studio: cannot autosave to %s: %s", self.autosave, e)

    # -- events -----------------------------------------------------------------------------

    async def broadcast(self, message: dict[str, Any]) -> None:
        text = json.dumps(message)
        for ws in list(self.clients):
            try:
                await ws.send_text(text)
            except Exception:  # a closed socket: forget it
                self.clients.discard(ws)

    def post(self, message: dict[str, Any]) -> None:
        """:meth:`broadcast` from another thread."""
        loop = self.loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                asyncio.run_coroutine_threadsafe(self.broadcast(message), loop)

    # -- work -------------------------------------------------------------------------------

    def warm_up(self) -> None:
        """Compile and load what the first edit, gesture and preview need (in the background)."""
        try:
            from tagbot.gesture import fit
            from tagbot.render import render_array

            s = np.linspace(0.0, 3.0, 60)
            tag = fit([np.c_[20 * s, 8 * np.sin(2 * s)]])
            view(design_from_tag(tag))
            render_array(tag, size=32)
        finally:
            self.ready.set()

    def shutdown(self) -> None:
        """Stop a draw (safely), wait for the workers and write the autosave."""
        if self.control is not None:
            self.control.stop()
        self.machine.shutdown(wait=True)
        self.compute.shutdown(wait=True)
        if self._autosave_handle is not None:
            self._autosave_handle.cancel()
        self.save_autosave()


def _started_executor(name: str) -> concurrent.futures.ThreadPoolExecutor:
    executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
    executor.submit(lambda: None).result()
    return executor


def _read_autosave(path: Path) -> Design | None:
    """The autosaved design, or None (missing or unreadable: the studio starts empty)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        design = data["design"]
        if data.get("format") != AUTOSAVE_FORMAT or not isinstance(design, dict):
            return None
        base = empty_design()
        if set(base) - set(design):
            return None
        apply(design, [])  # validates: its tag must build
        return design  # type: ignore[no-any-return]
    except (OSError, ValueError, KeyError, TypeError) as e:
        log.warning("studio: ignoring the autosave %s: %s", path, e)
        return None


# --------------------------------------------------------------------------- the app


def create_app(studio: Studio, port: int) -> Starlette:
    """The Starlette app of ``studio``, served at ``127.0.0.1:port``."""
    hosts = {f"127.0.0.1:{port}", f"localhost:{port}"}
    origins = {f"http://{h}" for h in hosts}
    pages = {p.name: p.read_bytes() for p in STATIC.iterdir() if p.suffix in _CONTENT_TYPES}

    def page(request: Request) -> Response:
        name = request.path_params.get("name", "index.html")
        body = pages.get(name)
        if body is None:
            raise HTTPError(404, f"{request.url.path}: not found")
        headers = {"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff"}
        if name == "index.html":
            headers["Content-Security-Policy"] = (
                "default-src 'self'; img-src 'self' data: blob:; connect-src 'self' "
                f"ws://127.0.0.1:{port} ws://localhost:{port}; frame-ancestors 'none'"
            )
            headers["Referrer-Policy"] = "no-referrer"
        return Response(body, media_type=_CONTENT_TYPES[Path(name).suffix], headers=headers)

    def answer(request: Request, started: float | None = None, **extra: Any) -> Response:
        arrays = "json" if request.query_params.get("arrays") == "json" else "packed"
        response = JSONResponse(studio.state(arrays) | extra)
        if started is not None:  # how long the server took, for the page's figures
            took = 1e3 * (time.perf_counter() - started)
            response.headers["Server-Timing"] = f"app;dur={took:.2f}"
        return response

    async def state(request: Request) -> Response:
        return answer(request)

    async def favicon(request: Request) -> Response:
        return Response(status_code=204)

    async def get_plan(request: Request) -> Response:
        tag = _tag(studio)
        if request.query_params.get("download"):
            data = await _in_worker(studio, plan_bytes, tag)
            return _attachment(data, f"{studio.name}.json", "application/json")
        from tagbot.io.planfile import tag_to_dict

        return JSONResponse(tag_to_dict(tag))

    async def put_plan(request: Request) -> Response:
        from tagbot.io.planfile import tag_from_dict

        data = await _json(request)
        tag = tag_from_dict(data)
        studio.commit(design_from_tag(tag, studio.design))
        return answer(request)

    async def patch_plan(request: Request) -> Response:
        started = time.perf_counter()
        data = await _object(request)
        group = data.get("group")
        if group is not None and (not isinstance(group, str) or len(group) > 100):
            raise StudioError("group: expected a short string or null")
        design, tag = apply_ops(studio.design, data.get("ops"))
        studio.commit(design, group, tag)
        return answer(request, started)

    async def undo(request: Request) -> Response:
        studio.history.undo()
        studio.schedule_autosave()
        return answer(request)

    async def redo(request: Request) -> Response:
        studio.history.redo()
        studio.schedule_autosave()
        return answer(request)

    async def gesture(request: Request) -> Response:
        data = await _object(request)
        started = time.perf_counter()
        new, tag = _fit_gesture(studio.design, data.get("points"))
        studio.commit(new, tag=tag)
        return answer(request, started, fit_ms=1e3 * (time.perf_counter() - started))

    async def open_file(request: Request) -> Response:
        from tagbot.inputs import MAX_INPUT_BYTES

        name = request.query_params.get("name", "upload")[:200]
        body = await _body(request, MAX_INPUT_BYTES)
        tag, traces = await _in_worker(studio, _read_source, body, name, studio.design["model"])
        design = design_from_tag(tag, studio.design)
        design["gestures"] = [_decimated(t.xy) for t in traces] if traces else []
        studio.commit(design)
        studio.name = Path(name).name.split(".")[0] or "studio"
        return answer(request)

    async def save(request: Request) -> Response:
        if studio.plan_path is None:
            raise HTTPError(409, "save: the studio was not started with a plan file (download)")
        from tagbot.io.planfile import save_plan

        save_plan(_tag(studio), studio.plan_path)
        return JSONResponse({"saved": str(studio.plan_path)})

    async def variations(request: Request) -> Response:
        from tagbot.gesture import new_seed, vary
        from tagbot.io.planfile import tag_to_dict

        data = await _object(request)
        count = integer(data.get("count", 4), "count", 1, MAX_VARIANTS)
        seed = data.get("seed")
        seed = new_seed() if seed is None else integer(seed, "seed", 0, 2**63 - 1)
        studio.variants = vary(_tag(studio), count, seed)
        variants = [{"tag": tag_to_dict(v), "motion": motion_view(v)} for v in studio.variants]
        return JSONResponse({"seed": seed, "variants": variants})

    async def adopt(request: Request) -> Response:
        data = await _object(request)
        if not studio.variants:
            raise HTTPError(409, "index: no variations to adopt (ask for some first)")
        i = integer(data.get("index"), "index", 0, len(studio.variants) - 1)
        studio.commit(design_from_tag(studio.variants[i], studio.design))
        return answer(request)

    async def brush(request: Request) -> Response:
        q = request.query_params
        width = _query_int(q, "width", 600, 16, MAX_PICTURE)
        height = _query_int(q, "height", 400, 16, MAX_PICTURE)
        drips = q.get("drips", "0") == "1"
        seed = _query_int(q, "seed", 1, 0, 2**31)
        tag = _tag(studio)
        data = await _in_worker(studio, _brush_png, tag, (width, height), drips, seed)
        return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})

    async def export(request: Request) -> Response:
        q = request.query_params
        fmt = q.get("format", "")
        if fmt not in ("png", "svg", "gif", "gcode", "json"):
            raise StudioError(f"format: unknown {fmt!r} (png, svg, gif, gcode or json)")
        drips = q.get("drips", "0") == "1"
        seed = _query_int(q, "seed", 1, 0, 2**31) if drips else None
        tag = _tag(studio)
        data = await _in_worker(studio, _export_bytes, tag, fmt, drips, seed)
        kind = {"png": "image/png", "svg": "image/svg+xml", "gif": "image/gif"}
        return _attachment(data, f"{studio.name}.{fmt}", kind.get(fmt, "text/plain"))

    async def draw_start(request: Request) -> Response:
        data = await _object(request)
        device = data.get("device", "grbl")
        if device not in DEVICES:
            raise StudioError(f"device: unknown {device!r} (grbl, dynamixel or axidraw)")
        profile = data.get("profile")
        if profile is not None and (device != "dynamixel" or profile not in SERIAL_ARMS):
            arms = " or ".join(SERIAL_ARMS)
            raise StudioError(f"profile: {profile!r} is not a serial arm of dynamixel ({arms})")
        if studio.draw.state in ("running", "paused", "preparing", "stopping"):
            raise HTTPError(409, "draw: a run is already going (stop it first)")
        tag = _tag(studio)
        port = studio.machine_port
        studio.draw = DrawState("preparing", device, port, profile=profile)
        try:
            job = await _in_worker(studio, _prepare, tag, device, port, profile)
        except BaseException:
            studio.draw = DrawState()
            raise
        stamp = time.strftime("%Y%m%d-%H%M%S")
        machine = profile or device
        folder = studio.runs / f"{studio.name}-{machine}-{stamp}"
        n = 1
        while folder.exists():
            n += 1
            folder = studio.runs / f"{studio.name}-{machine}-{stamp}-{n}"
        studio.control = StopControl()
        studio.draw = DrawState("running", device, port, str(folder), profile=profile)
        studio.machine.submit(_run_draw, studio, tag, job, folder, studio.control)
        return JSONResponse(studio.draw.as_dict(), status_code=202)

    async def draw_status(request: Request) -> Response:
        return JSONResponse(studio.draw.as_dict())

    async def draw_pause(request: Request) -> Response:
        if studio.control is None or studio.draw.state != "running":
            raise HTTPError(409, "pause: no run is going")
        studio.control.pause()
        studio.draw.state = "paused"
        await studio.broadcast({"type": "draw", **studio.draw.as_dict()})
        return JSONResponse(studio.draw.as_dict())

    async def draw_resume(request: Request) -> Response:
        if studio.control is None or studio.draw.state != "paused":
            raise HTTPError(409, "resume: no run is paused")
        studio.control.resume()
        studio.draw.state = "running"
        await studio.broadcast({"type": "draw", **studio.draw.as_dict()})
        return JSONResponse(studio.draw.as_dict())

    async def draw_stop(request: Request) -> Response:
        if studio.control is None or studio.draw.state not in ("running", "paused"):
            raise HTTPError(409, "stop: no run is going")
        studio.control.stop()
        studio.draw.state = "stopping"
        return JSONResponse(studio.draw.as_dict())

    def socket_edit(text: str) -> dict[str, Any]:
        """An edit sent on the WebSocket: ``{"id", "ops", "group"}`` as for ``PATCH /api/plan``,
        answered in order with ``{"type": "state", "id", "state"}`` or ``{"type": "error",
        "id", "error"}`` (one connection: no HTTP request per pointer move)."""
        started = time.perf_counter()
        ident = None
        try:
            if len(text) > MAX_BODY:
                raise StudioError(f"message: larger than {MAX_BODY} bytes")
            try:
                data = json.loads(text, parse_constant=_no_constants)
            except (json.JSONDecodeError, RecursionError) as e:
                raise StudioError(f"message: not JSON ({e})") from e
            if not isinstance(data, dict):
                raise StudioError("message: expected a JSON object")
            ident = data.get("id")
            if not (ident is None or (isinstance(ident, int) and not isinstance(ident, bool))):
                raise StudioError("id: expected a whole number")
            group = data.get("group")
            if group is not None and (not isinstance(group, str) or len(group) > 100):
                raise StudioError("group: expected a short string or null")
            design, tag = apply_ops(studio.design, data.get("ops"))
            studio.commit(design, group, tag)
            state = studio.state()
            state["server_ms"] = 1e3 * (time.perf_counter() - started)
            return {"type": "state", "id": ident, "state": state}
        except (TagbotError, ValueError) as e:
            return {"type": "error", "id": ident, "error": _one_line(str(e))}

    async def events(ws: WebSocket) -> None:
        await ws.accept()
        studio.clients.add(ws)
        try:
            await ws.send_text(json.dumps({"type": "hello", "draw": studio.draw.as_dict()}))
            while True:
                text = await ws.receive_text()
                await ws.send_text(json.dumps(socket_edit(text), separators=(",", ":")))
        except WebSocketDisconnect:
            pass
        finally:
            studio.clients.discard(ws)

    def handler(
        fn: Callable[[Request], Awaitable[Response]] | Callable[[Request], Response],
    ) -> Callable[[Request], Awaitable[Response]]:
        async def wrapped(request: Request) -> Response:
            try:
                result = fn(request)
                if asyncio.iscoroutine(result):
                    result = await result
                return result  # type: ignore[return-value]
            except HTTPError as e:
                return JSONResponse({"error": str(e)}, status_code=e.status)
            except (TagbotError, ValueError) as e:
                return JSONResponse({"error": _one_line(str(e))}, status_code=400)

        return wrapped

    routes = [
        Route("/", handler(page)),
        Route("/static/{name}", handler(page)),
        Route("/favicon.ico", handler(favicon)),
        Route("/api/state", handler(state)),
        Route("/api/plan", handler(get_plan), methods=["GET"]),
        Route("/api/plan", handler(put_plan), methods=["PUT"]),
        Route("/api/plan", handler(patch_plan), methods=["PATCH"]),
        Route("/api/undo", handler(undo), methods=["POST"]),
        Route("/api/redo", handler(redo), methods=["POST"]),
        Route("/api/gesture", handler(gesture), methods=["POST"]),
        Route("/api/open", handler(open_file), methods=["POST"]),
        Route("/api/save", handler(save), methods=["POST"]),
        Route("/api/variations", handler(variations), methods=["POST"]),
        Route("/api/variations/adopt", handler(adopt), methods=["POST"]),
        Route("/api/brush.png", handler(brush)),
        Route("/api/export", handler(export)),
        Route("/api/draw", handler(draw_start), methods=["POST"]),
        Route("/api/draw", handler(draw_status), methods=["GET"]),
        Route("/api/draw/pause", handler(draw_pause), methods=["POST"]),
        Route("/api/draw/resume", handler(draw_resume), methods=["POST"]),
        Route("/api/draw/stop", handler(draw_stop), methods=["POST"]),
        WebSocketRoute("/ws", events),
    ]

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> Any:
        studio.loop = asyncio.get_running_loop()
        studio.compute.submit(studio.warm_up)
        try:
            yield
        finally:
            for ws in list(studio.clients):
                with contextlib.suppress(Exception):
                    await ws.close(1001)
            studio.shutdown()  # waits for a stopped draw; the loop has nothing else to do

    app = Starlette(routes=routes, lifespan=lifespan)
    return _Guard(app, studio.token, hosts, origins)  # type: ignore[return-value]


class _Guard:
    """ASGI wrapper: Host, Origin and token checks before any route (HTTP and WebSocket)."""

    def __init__(self, app: Any, token: str, hosts: set[str], origins: set[str]) -> None:
        self.app, self.token, self.hosts, self.origins = app, token, hosts, origins

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)  # type: ignore[no-any-return]
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        problem = self.refusal(scope, headers)
        if problem is None:
            return await self.app(scope, receive, send)  # type: ignore[no-any-return]
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008, "reason": problem[:120]})
            return None
        response = JSONResponse({"error": problem}, status_code=403)
        return await response(scope, receive, send)  # type: ignore[no-any-return]

    def refusal(self, scope: Any, headers: dict[str, str]) -> str | None:
        """Why the request is refused, or None."""
        host = headers.get("host", "")
        if host not in self.hosts:
            return f"host {host!r} is not this studio (use http://{sorted(self.hosts)[0]})"
        origin = headers.get("origin")
        if origin is not None and origin not in self.origins:
            return f"origin {origin!r} may not use this studio"
        path = scope["path"]
        if path.startswith("/static/") or path == "/favicon.ico":
            return None
        query = dict(
            part.split("=", 1) if "=" in part else (part, "")
            for part in scope.get("query_string", b"").decode("latin-1").split("&")
        )
        given = headers.get("x-tagbot-token") or query.get("token", "")
        if not secrets.compare_digest(given.encode(), self.token.encode()):
            return "missing or wrong session token (open the URL tagbot studio printed)"
        return None


# --------------------------------------------------------------------------- helpers


def _one_line(message: str) -> str:
    return " ".join(message.split())


async def _body(request: Request, limit: int) -> bytes:
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit:
        raise HTTPError(413, f"body: larger than {limit} bytes")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise HTTPError(413, f"body: larger than {limit} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


def _no_constants(name: str) -> Any:
    raise StudioError(f"body: {name} is not a JSON number")


async def _json(request: Request) -> Any:
    raw = await _body(request, MAX_BODY)
    try:
        return json.loads(raw.decode("utf-8"), parse_constant=_no_constants)
    except UnicodeDecodeError as e:
        raise StudioError(f"body: not UTF-8 text (byte {e.start})") from e
    except json.JSONDecodeError as e:
        raise StudioError(f"body: not JSON (line {e.lineno}, column {e.colno}: {e.msg})") from e
    except RecursionError as e:
        raise StudioError("body: not JSON (nested too deeply)") from e


async def _object(request: Request) -> dict[str, Any]:
    data = await _json(request)
    if not isinstance(data, dict):
        raise StudioError("body: expected a JSON object")
    return data


def _query_int(q: Any, name: str, default: int, lo: int, hi: int) -> int:
    raw = q.get(name)
    if raw is None:
        return default
    if not raw.isdigit():
        raise StudioError(f"{name}: expected a whole number, got {raw[:20]!r}")
    return integer(int(raw), name, lo, hi)


def _tag(studio: Studio) -> Tag:
    tag = tag_of(studio.design)
    if tag is None:
        raise HTTPError(409, "plan: the design has no plan yet (draw a gesture or two targets)")
    return tag


async def _in_worker(studio: Studio, fn: Callable[..., Any], *args: Any) -> Any:
    return await asyncio.wrap_future(studio.compute.submit(fn, *args))


def _attachment(data: bytes, name: str, kind: str) -> Response:
    return Response(
        data,
        media_type=kind,
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


def _decimated(xy: Any, limit: int = 4000) -> list[list[float]]:
    xy = np.asarray(xy, dtype=float)
    step = max(1, math.ceil(len(xy) / limit))
    return np.round(xy[::step], 4).tolist()  # type: ignore[no-any-return]


def _fit_gesture(design: Design, points: Any) -> tuple[Design, Tag | None]:
    """``design`` with the gesture ``points`` (``[[x, y, t], ...]``) fitted into a new plan."""
    from tagbot.gesture import fit
    from tagbot.inputs import Trace

    if not isinstance(points, list) or not points:
        raise StudioError("points: expected a non-empty list of [x, y, t]")
    if len(points) > MAX_GESTURE_POINTS:
        raise StudioError(f"points: at most {MAX_GESTURE_POINTS}, got {len(points)}")
    rows = []
    for i, p in enumerate(points):
        if not isinstance(p, list) or len(p) != 3:
            raise StudioError(f"points[{i}]: expected [x, y, t]")
        rows.append(
            [
                number(p[0], f"points[{i}][0]", -1e6, 1e6),
                number(p[1], f"points[{i}][1]", -1e6, 1e6),
                number(p[2], f"points[{i}][2]", 0.0, 3600.0),
            ]
        )
    data = np.array(rows)
    t = data[:, 2] - data[0, 2]
    if np.any(np.diff(t) < 0):
        raise StudioError("points: times must not decrease")
    try:
        trace = Trace(data[:, :2], t)
    except TagbotError as e:
        raise StudioError(f"points: {e}") from e
    options: dict[str, Any] = {
        "dt_min": design["dt_min"],
        "dt_max": design["dt_max"],
        "mu": design["mu"],
        "sigma": design["sigma"],
    }
    # The paper's §6.6 fit of the shape, with the design's μ, σ and Δt range, so that its handles
    # edit it in the same terms (not the hand's own rhythm, where tagbot's fit can also match it).
    if "timing" in inspect.signature(fit).parameters:
        options["timing"] = "ignore"
    tag = fit([trace], model=design["model"], **options)
    fitted = design_from_tag(tag, design)
    new = apply(design, [])
    for draft in fitted["plans"]:
        draft["lift"] = design["lift"]
        if not new["plans"]:
            draft["start"] = 0.0
        else:
            draft.pop("start", None)
        new["plans"].append(draft)
    new["gestures"].append(_decimated(data[:, :2]))
    return apply_ops(new, [])


def _read_source(data: bytes, name: str, model: str) -> tuple[Tag, list[Any] | None]:
    """A plan file as is, or any trace file fitted with ``model`` (as ``tagbot draw`` does)."""
    from tagbot.source import read_source

    try:
        return read_source(data, name, model)
    except TagbotError as e:
        raise StudioError(str(e)) from e


def _brush_png(tag: Tag, size: tuple[int, int], drips: bool, seed: int) -> bytes:
    from PIL import Image

    from tagbot.render import render_array

    pixels = render_array(tag, size=size, drips=drips, seed=seed if drips else None)
    out = io.BytesIO()
    Image.fromarray(pixels, "RGBA").save(out, format="PNG")
    return out.getvalue()


def _export_bytes(tag: Tag, fmt: str, drips: bool, seed: int | None) -> bytes:
    """The file the CLI writes: ``tagbot render -o x.png|svg|gif``, ``tagbot gcode``, the plan."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"tag.{fmt}"
        if fmt == "json":
            return plan_bytes(tag)
        if fmt == "gcode":
            from tagbot.plotter.place import place
            from tagbot.plotter.profile import load_profile
            from tagbot.plotter.program import build_program

            machine = load_profile(None, ())
            build_program(place(tag, machine), machine).write(path)
        else:
            from tagbot.render import render
            from tagbot.render.brush import Brush

            render(tag, path, drips=drips, seed=seed, brush=Brush())
        return path.read_bytes()


def _prepare(tag: Tag, device: str, port: str | None, profile: str | None = None) -> Any:
    from tagbot.draw import prepare

    return prepare(tag, device=device, port=port, profile=profile)


def _machine_frame(job: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per executed step (line, tick or move): machine position and pen, and the placement
    ``machine = matrix @ tag + offset``."""
    if getattr(job, "device", None) == "axidraw":  # one position per EBB command (moves.txt)
        entries = job.job.entries
        steps = np.array([e.steps for e in entries], dtype=np.int64).reshape(-1, 2)
        pens = np.array([e.pen for e in entries], dtype=bool)
        return job.job.xy(steps), pens, job.setpoints.matrix, job.setpoints.offset
    program = job.program
    if hasattr(program, "line_xy"):  # the plotter: one position per G-code line
        sp = job.setpoints
        return program.line_xy, program.line_pen, sp.matrix, sp.offset
    sp = program.setpoints  # the arm: one setpoint per tick
    return sp.xy, sp.pen, sp.placement.matrix, sp.placement.offset


def _to_tag(xy: np.ndarray, matrix: np.ndarray, offset: np.ndarray) -> np.ndarray:
    return np.linalg.solve(matrix, (np.asarray(xy, dtype=float) - offset).T).T


def _run_draw(studio: Studio, tag: Tag, job: Any, folder: Path, control: StopControl) -> None:
    """Draw in the machine worker, posting progress and the executed trace as events."""
    from tagbot.draw import draw

    steps, pens, matrix, offset = _machine_frame(job)
    steps = _to_tag(steps, matrix, offset)
    sent = {"done": 0, "at": 0.0}
    state = studio.draw

    def progress(done: int, total: int) -> None:
        control.check()
        state.done, state.total = done, total
        now = time.monotonic()
        if now - sent["at"] < EVENT_INTERVAL and done < total:
            return
        first, last = sent["done"], min(done, len(steps))
        points = [
            [round(float(x), 4), round(float(y), 4), int(pens[i])]
            for i, (x, y) in enumerate(steps[first:last].tolist(), start=first)
        ]
        sent["done"], sent["at"] = last, now
        studio.post({"type": "draw", **state.as_dict(), "points": points})

    final: dict[str, Any] = {}
    try:
        result = draw(tag, folder, prepared=job, progress=progress, control=control)
        state.state, state.summary = "done", _summary(result.report)
    except (Interrupted, KeyboardInterrupt) as e:
        state.state, state.error = "stopped", str(e) or "stopped"
    except TagbotError as e:
        state.state, state.error = "failed", _one_line(str(e))
    except Exception as e:  # a bug: say so on the page, and in the log
        log.exception("studio: draw failed")
        state.state, state.error = "failed", f"{type(e).__name__}: {e}"
    finally:
        executed = folder / "executed.csv"
        if executed.exists():
            with contextlib.suppress(ValueError, OSError):
                rows = np.loadtxt(executed, delimiter=",", skiprows=1, ndmin=2)
                if rows.size:
                    xy = _to_tag(rows[:, 1:3], matrix, offset)
                    step = max(1, math.ceil(len(rows) / 20000))
                    final["executed"] = [
                        [round(float(x), 4), round(float(y), 4), int(p > 0.5)]
                        for (x, y), p in zip(xy[::step], rows[::step, 3], strict=True)
                    ]
        studio.post({"type": "draw", **state.as_dict(), **final})


def _summary(report: dict[str, Any]) -> dict[str, Any]:
    keys = (
        "completed",
        "executed",
        "total",
        "planned_duration_s",
        "executed_duration_s",
        "path_deviation_mean_mm",
        "path_deviation_max_mm",
        "speed_snr_db",
    )
    return {k: report[k] for k in keys if k in report}


# --------------------------------------------------------------------------- serving


class StudioServer:
    """uvicorn serving a :class:`Studio` on ``127.0.0.1:port`` (0: any free port)."""

    def __init__(self, studio: Studio, port: int = 0) -> None:
        import uvicorn

        from tagbot.errors import InputError

        self.studio = studio
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        # Answers go out at once (accepted sockets inherit it): no 40 ms Nagle/delayed-ACK stall
        # on small answers.
        self.socket.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            self.socket.bind(("127.0.0.1", port))
        except OSError as e:
            self.socket.close()
            raise InputError(f"--port {port}: cannot listen on 127.0.0.1 ({e.strerror})") from e
        self.port = int(self.socket.getsockname()[1])
        # Listening from now on: a browser opened on the printed URL before uvicorn has started
        # waits in the backlog instead of being refused.
        self.socket.listen(128)
        config = uvicorn.Config(
            create_app(studio, self.port),
            log_level="warning",
            ws="websockets-sansio",
            lifespan="on",
            timeout_graceful_shutdown=3,
        )
        self.server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page, with the session token."""
        return f"http://127.0.0.1:{self.port}/?token={self.studio.token}"

    def run(self) -> None:
        """Serve until Ctrl-C (uvicorn handles the signal and shuts down cleanly)."""
        try:
            self.server.run(sockets=[self.socket])
        finally:
            self.socket.close()

    def start(self, timeout: float = 30.0) -> None:
        """Serve in a background thread; returns once the server accepts connections."""
        self._thread = threading.Thread(target=self.run, name="tagbot-studio-server")
        self._thread.start()
        deadline = time.monotonic() + timeout
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the studio server did not start")
            time.sleep(0.01)

    def stop(self) -> None:
        """Shut down (as Ctrl-C does) and wait for the server thread."""
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join()
            self._thread = None
