"""The studio in a real browser: drag latency, gesture-to-plan time, frames while a draw streams.

Run from the repository root (needs Debian's chromium at /usr/bin/chromium and Playwright)::

    python benchmarks/bench_studio.py [--moves 200] [--gestures 10]

A real server (:class:`tagbot.studio.server.StudioServer`) on loopback and headless chromium
driven by Playwright. Figures are measured inside the page with ``performance.now()``:

- **handle drag** on a 30-stroke tag (3 plans of 10 strokes): from the ``pointermove`` event to
  the trajectory and speed plot redrawn with the server's answer (``redrawn``), and to the next
  animation frame after it (``on screen``). Moves come at 60 Hz at most, as from a real pointer
  (no catch-up bursts); the page sends edits on the WebSocket, two in flight at most, and only
  the latest waits. Goal: median ≤ 16 ms,
  p95 ≤ 33 ms.
- **gesture → plan**: a 300-point gesture drawn with the mouse; from ``pointerup`` to the fitted
  plan drawn (and its frame); ``fit`` is the server's fit alone. Goal ≤ 100 ms.
- **draw streaming**: the 30-stroke tag drawn on the simulated plotter from the page; the longest
  interval between animation frames while it streams. Goal: none > 100 ms.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from tagbot.io.planfile import tag_to_dict
from tagbot.model import random_plan, sequence
from tagbot.studio.server import Studio, StudioServer

CHROMIUM = "/usr/bin/chromium"
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else math.nan


def figures(name: str, values: list[float]) -> str:
    return (
        f"{name:<28} n={len(values):<4d} median {statistics.median(values):6.1f} ms  "
        f"p95 {percentile(values, 95):6.1f} ms  max {max(values):6.1f} ms"
    )


def settle(page: Any) -> None:
    page.wait_for_function("!window.studio.busy && !window.studio.pending")


def drag_handle(page: Any, selector: str, moves: int, radius: float) -> None:
    """Drag the handle at ``selector`` around a circle, one move every 1/60 s."""
    box = page.locator(selector).bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.down()
    period = 1 / 60
    for i in range(1, moves + 1):
        # At most one move a frame, as a real pointer delivers them: a late move is not followed
        # by a burst catching up (Playwright's own round trip can be late on a busy machine).
        began = time.perf_counter()
        a = 2 * math.pi * i / 90
        page.mouse.move(cx + radius * math.sin(a), cy - radius * (1 - math.cos(a)))
        wait = began + period - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    settle(page)
    page.mouse.up()
    settle(page)


def screenshots(folder: Path) -> None:
    """The studio's main states as PNG files in ``folder`` (for the README)."""
    from playwright.sync_api import sync_playwright

    from tagbot.io.planfile import load_plan

    example = Path(__file__).resolve().parent.parent / "tagbot" / "examples" / "cae.json"
    work = Path(tempfile.mkdtemp(prefix="studio-shots-"))
    studio = Studio(tag=load_plan(example), autosave=None, runs=work / "runs", name="cae")
    server = StudioServer(studio)
    server.start()
    studio.ready.wait(600)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page = browser.new_page(viewport={"width": 1500, "height": 1180}, bypass_csp=True)
            page.goto(server.url)
            page.wait_for_function("window.studio && window.studio.ready === true")
            page.check("#drips")
            page.wait_for_timeout(400)
            page.wait_for_function("!window.studio.brushBusy")
            page.wait_for_timeout(300)
            page.screenshot(path=str(folder / "studio-edit.png"))

            page.click("#vary")
            page.wait_for_function("document.querySelectorAll('#variants figure').length === 4")
            page.screenshot(path=str(folder / "studio-variations.png"))

            page.click("#draw")
            page.wait_for_function(
                "['done', 'stopped', 'failed'].some(s =>"
                " document.getElementById('draw-status').textContent.startsWith(s))",
                timeout=600_000,
            )
            page.wait_for_timeout(300)
            page.screenshot(path=str(folder / "studio-draw.png"))

            page.click("#clear")
            page.wait_for_function("window.studio.state.tag === null")
            box = page.locator("#editor").bounding_box()
            s = np.linspace(0.0, 1.0, 220)
            # A quick looped "e" then a flick: one gesture, drawn with the mouse.
            xs = box["x"] + 260 + 520 * s + 90 * np.sin(2 * math.pi * 2 * s)
            ys = box["y"] + 430 - 150 * np.sin(2 * math.pi * 2 * s + 1.2) * (1 - 0.5 * s)
            page.mouse.move(float(xs[0]), float(ys[0]))
            page.mouse.down()
            for x, y in zip(xs[1:], ys[1:], strict=True):
                page.mouse.move(float(x), float(y))
            page.mouse.up()
            page.wait_for_function("window.studio.state.tag !== null")
            page.wait_for_timeout(400)
            page.wait_for_function("!window.studio.brushBusy")
            page.wait_for_timeout(300)
            page.screenshot(path=str(folder / "studio-gesture.png"))
            browser.close()
    finally:
        server.stop()
    for name in ("edit", "variations", "draw", "gesture"):
        print(f"wrote {folder / f'studio-{name}.png'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--moves", type=int, default=200, help="Pointer moves per drag.")
    parser.add_argument("--gestures", type=int, default=10, help="300-point gestures drawn.")
    parser.add_argument(
        "--screenshots",
        metavar="DIR",
        type=Path,
        default=None,
        help="Instead of measuring, save the main states as DIR/studio-*.png (the README's).",
    )
    args = parser.parse_args()
    if args.screenshots is not None:
        screenshots(args.screenshots)
        return

    from playwright.sync_api import sync_playwright

    rng = np.random.default_rng(14)
    tag = sequence([random_plan(rng, targets=(11, 11)) for _ in range(3)], 0.3)
    assert tag.n_strokes == 30
    folder = Path(tempfile.mkdtemp(prefix="bench-studio-"))
    studio = Studio(tag=tag, autosave=folder / "autosave.json", runs=folder / "runs")
    server = StudioServer(studio)
    server.start()
    studio.ready.wait(600)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 860}, bypass_csp=True)
            page.goto(server.url)
            page.wait_for_function("window.studio && window.studio.ready === true", timeout=600_000)
            print(
                f"{time.strftime('%Y-%m-%d')}  {platform.platform()}  {platform.processor() or ''}"
                f"  {os.cpu_count()} CPUs  chromium {browser.version}  python"
                f" {platform.python_version()}"
            )
            print(f"tag: {tag.n_strokes} strokes in {len(tag.plans)} plans")

            for selector, label in (
                ('circle.phi[data-plan="1"][data-stroke="4"][data-end="1"]', "phi handle"),
                ('circle.target[data-plan="1"][data-index="5"]', "target"),
                ('rect.dt[data-plan="1"][data-stroke="5"]', "dt handle"),
            ):
                page.evaluate(
                    "() => { for (const k of ['drag', 'dragFrame', 'dragServer', 'dragRender'])"
                    " window.studio.stats[k] = []; }"
                )
                drag_handle(page, selector, args.moves, 40.0)
                redrawn = page.evaluate("window.studio.stats.drag")
                shown = page.evaluate("window.studio.stats.dragFrame")
                print(figures(f"drag {label}: redrawn", redrawn))
                print(figures(f"drag {label}: on screen", shown))
                server_ms = page.evaluate("window.studio.stats.dragServer")
                render_ms = page.evaluate("window.studio.stats.dragRender")
                print(figures("  of which server", server_ms))
                print(figures("  of which page redraw", render_ms))

            box = page.locator("#editor").bounding_box()
            results = []
            for g in range(args.gestures):
                page.click("#clear")
                settle(page)
                page.wait_for_function("window.studio.state.tag === null")
                # A writer takes more than a moment between gestures: the brush preview of the
                # last one is done before the next starts.
                page.wait_for_timeout(300)
                page.wait_for_function("!window.studio.brushBusy")
                page.evaluate("() => { window.studio.stats.gesture = []; }")
                s = np.linspace(0.0, 1.0, 300)
                xs = box["x"] + 150 + 700 * s
                ys = (
                    box["y"] + 430 - 180 * np.sin(2 * math.pi * (1.5 + 0.1 * g) * s) * (1 - 0.4 * s)
                )
                page.mouse.move(float(xs[0]), float(ys[0]))
                page.mouse.down()
                for x, y in zip(xs[1:], ys[1:], strict=True):
                    page.mouse.move(float(x), float(y))
                page.mouse.up()
                page.wait_for_function("window.studio.stats.gesture.length === 1", timeout=60_000)
                results.append(page.evaluate("window.studio.stats.gesture[0]"))
            print(figures("gesture -> plan drawn", [r["ms"] for r in results]))
            print(figures("gesture -> plan on screen", [r["frame"] for r in results]))
            print(figures("gesture: server fit alone", [r["fit_ms"] for r in results]))
            print(f"{'gesture points':<28} {sorted({r['points'] for r in results})}")

            httpx.put(
                f"http://127.0.0.1:{server.port}/api/plan",
                json=tag_to_dict(tag),
                headers={"X-Tagbot-Token": studio.token},
                timeout=60,
            ).raise_for_status()
            page.reload()
            page.wait_for_function("window.studio && window.studio.ready === true")
            page.evaluate(
                "() => { window.studio.stats.frames = [];"
                " window.studio.stats.recordFrames = true; }"
            )
            started = time.perf_counter()
            page.click("#draw")
            page.wait_for_function(
                "['done', 'stopped', 'failed'].some(s =>"
                " document.getElementById('draw-status').textContent.startsWith(s))",
                timeout=600_000,
            )
            took = time.perf_counter() - started
            page.evaluate("() => { window.studio.stats.recordFrames = false; }")
            frames = page.evaluate("window.studio.stats.frames")
            status = page.locator("#draw-status").text_content()
            events = page.evaluate("window.studio.stats.drawEvents")
            print(
                f"{'draw streaming':<28} {took:.1f} s, {events} events, {len(frames)} frames:"
                f" median {statistics.median(frames):.1f} ms, p99 {percentile(frames, 99):.1f} ms,"
                f" longest {max(frames):.1f} ms ({status.split(' — ')[0]})"
            )
            browser.close()
    finally:
        server.stop()


if __name__ == "__main__":
    main()
