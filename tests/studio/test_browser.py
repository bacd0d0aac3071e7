"""The studio in a real browser: chromium driven by Playwright against a real server."""

from __future__ import annotations

import itertools
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tagbot.io.planfile import load_plan, tag_to_dict
from tests.studio.conftest import PLAN, Running


def settle(page: Any) -> None:
    """Wait until the page has no edit in flight or waiting."""
    page.wait_for_function("!window.studio.busy && !window.studio.pending")


def centre(page: Any, selector: str) -> tuple[float, float]:
    box = page.locator(selector).bounding_box()
    assert box is not None, f"{selector} is not on the page"
    return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2


def drag(page: Any, start: tuple[float, float], end: tuple[float, float], steps: int = 6) -> None:
    page.mouse.move(*start)
    page.mouse.down()
    page.mouse.move(*end, steps=steps)
    settle(page)
    page.mouse.up()
    settle(page)


def editor_origin(page: Any) -> tuple[float, float]:
    box = page.locator("#editor").bounding_box()
    return box["x"], box["y"]


def to_screen(page: Any, xy: list[float]) -> tuple[float, float]:
    view = page.evaluate("window.studio.view")
    x0, y0 = editor_origin(page)
    return x0 + view["ox"] + view["s"] * xy[0], y0 + view["oy"] - view["s"] * xy[1]


def strokes(plan: dict[str, Any]) -> list[dict[str, float]]:
    return plan["plans"][0]["strokes"]  # type: ignore[no-any-return]


def test_page_shows_the_plan(page: Any, running: Running) -> None:
    assert page.locator("circle.target").count() == 4
    assert page.locator("circle.phi").count() == 6  # ΓΛ*: φ1 and φ2 per stroke
    assert page.locator("rect.dt").count() == 2  # strokes after the first
    assert page.evaluate("window.studio.stats.drawn.paths") == 1  # one pen-down run
    drawn = page.evaluate("window.studio.state.motion.x.length")
    assert drawn == len(running.state()["motion"]["x"])


def test_gesture_becomes_a_plan_of_its_shape(page: Any, running: Running) -> None:
    page.click("#clear")
    settle(page)
    page.wait_for_function("window.studio.state.tag === null")
    view = page.evaluate("window.studio.view")
    x0, y0 = editor_origin(page)
    corners = [(250, 500), (450, 180), (650, 520), (850, 200)]  # a W, in editor pixels
    page.mouse.move(x0 + corners[0][0], y0 + corners[0][1])
    page.mouse.down()
    drawn = [corners[0]]
    for (ax, ay), (bx, by) in itertools.pairwise(corners):
        for u in np.linspace(0, 1, 30)[1:]:
            p = (ax + u * (bx - ax), ay + u * (by - ay))
            page.mouse.move(x0 + p[0], y0 + p[1])
            drawn.append(p)
    page.mouse.up()
    page.wait_for_function("window.studio.state.tag !== null", timeout=60_000)
    state = running.state()
    assert len(state["design"]["plans"]) == 1
    assert len(state["design"]["gestures"]) == 1
    gesture = np.array(
        [[(X - view["ox"]) / view["s"], (view["oy"] - Y) / view["s"]] for X, Y in drawn]
    )
    motion = state["motion"]
    path = np.c_[motion["x"], motion["y"]][np.array(motion["pen"]) == 1]
    size = float(np.hypot(*np.ptp(gesture, axis=0)))
    # Every gesture point is near the trajectory, and every trajectory point near the gesture.
    d = np.hypot(*(gesture[:, None, :] - path[None, :, :]).transpose(2, 0, 1))
    # (A smooth gesture model rounds the W's sharp corners a little: hence the looser maximum.)
    assert d.min(axis=1).mean() < 0.015 * size and d.min(axis=1).max() < 0.06 * size
    assert d.min(axis=0).mean() < 0.015 * size and d.min(axis=0).max() < 0.06 * size
    targets = np.array(state["design"]["plans"][0]["targets"])
    assert np.hypot(*(targets[0] - gesture[0])) < 0.03 * size
    assert np.hypot(*(targets[-1] - gesture[-1])) < 0.03 * size
    assert len(targets) >= 4  # the W's corners are targets
    # The page drew the fitted trajectory over the faded gesture.
    drawn = page.evaluate("window.studio.stats.drawn")
    assert drawn["gestures"] == 1 and drawn["paths"] == 1


def test_drag_a_target_moves_exactly_that_target(page: Any, running: Running) -> None:
    before = running.plan()
    start = centre(page, 'circle.target[data-plan="0"][data-index="2"]')
    start = (round(start[0]), round(start[1]))
    drag(page, start, (start[0] + 40, start[1] - 30))
    after = running.plan()
    s = page.evaluate("window.studio.view.s")
    moved = after["plans"][0]["targets"][2]
    expected = [90.0 + 40 / s, 60.0 + 30 / s]
    assert moved == pytest.approx(expected, abs=1e-6)
    rest = [t for i, t in enumerate(after["plans"][0]["targets"]) if i != 2]
    assert rest == [t for i, t in enumerate(before["plans"][0]["targets"]) if i != 2]
    assert strokes(after) == strokes(before)
    # One drag is one undo step.
    page.click("#undo")
    settle(page)
    page.wait_for_function("!window.studio.state.can_undo || true")
    assert running.plan() == before
    page.click("#redo")
    settle(page)
    assert running.plan() == after


def test_drag_a_phi_handle_sets_that_tangent(page: Any, running: Running) -> None:
    before = running.plan()
    a, b = np.array(PLAN["plans"][0]["targets"][1]), np.array(PLAN["plans"][0]["targets"][2])
    alpha = math.atan2(*(b - a)[::-1])
    handle = centre(page, 'circle.phi[data-plan="0"][data-stroke="1"][data-end="1"]')
    want = 0.6
    target = to_screen(page, list(a))
    drop = (target[0] + 120 * math.cos(alpha + want), target[1] - 120 * math.sin(alpha + want))
    drag(page, handle, drop)
    after = running.plan()
    assert strokes(after)[1]["phi1"] == pytest.approx(want, abs=0.01)
    for j, (old, new) in enumerate(zip(strokes(before), strokes(after), strict=True)):
        for name in ("dt", "mu", "sigma", "phi2") if j == 1 else old:
            assert new[name] == old[name], (j, name)
    assert after["plans"][0]["targets"] == before["plans"][0]["targets"]
    # The arrival handle of the same stroke sets phi2 alone.
    handle = centre(page, 'circle.phi[data-plan="0"][data-stroke="1"][data-end="2"]')
    end = to_screen(page, list(b))
    drop = (end[0] - 120 * math.cos(alpha - 0.3), end[1] + 120 * math.sin(alpha - 0.3))
    drag(page, handle, drop)
    again = running.plan()
    assert strokes(again)[1]["phi2"] == pytest.approx(-0.3, abs=0.01)
    assert strokes(again)[1]["phi1"] == strokes(after)[1]["phi1"]


def test_drag_a_dt_handle_sets_dt_within_the_range(page: Any, running: Running) -> None:
    before = running.plan()
    design = running.state()["design"]
    lo, hi = design["dt_min"], design["dt_max"]
    selector = 'rect.dt[data-plan="0"][data-stroke="2"]'
    target = to_screen(page, PLAN["plans"][0]["targets"][2])
    handle = centre(page, selector)
    direction = np.subtract(handle, target)
    direction /= np.hypot(*direction)
    far = tuple(np.add(target, 200 * direction))
    drag(page, handle, far)
    assert strokes(running.plan())[2]["dt"] == hi  # past the longest: Δt_max exactly
    drag(page, centre(page, selector), target)
    assert strokes(running.plan())[2]["dt"] == lo  # onto the target: Δt_min exactly
    half = 14 + 0.5 * (74 - 14)  # the page's handle lengths at Δt_min and Δt_max, px
    drag(page, centre(page, selector), tuple(np.add(target, half * direction)))
    after = running.plan()
    assert strokes(after)[2]["dt"] == pytest.approx(0.5 * (lo + hi), abs=0.02 * (hi - lo))
    for j, (old, new) in enumerate(zip(strokes(before), strokes(after), strict=True)):
        assert {k: v for k, v in new.items() if (j, k) != (2, "dt")} == {
            k: v for k, v in old.items() if (j, k) != (2, "dt")
        }
    assert after["plans"][0]["targets"] == before["plans"][0]["targets"]


def test_click_targets_makes_strokes_at_mid_range(page: Any, running: Running) -> None:
    page.click("#clear")
    settle(page)
    page.check("input[name=tool][value=targets]")
    x0, y0 = editor_origin(page)
    for X, Y in [(300, 400), (500, 300), (700, 420)]:
        page.mouse.click(x0 + X, y0 + Y)
        settle(page)
    plan = running.plan()
    design = running.state()["design"]
    assert len(plan["plans"]) == 1 and len(plan["plans"][0]["targets"]) == 3
    mid = 0.5 * (design["dt_min"] + design["dt_max"])
    assert [s["dt"] for s in strokes(plan)] == [0.0, mid]
    assert all(s["phi1"] == 0.0 and s["phi2"] == 0.0 for s in strokes(plan))
    # A new plan after a pen lift.
    page.click("#new-plan")
    for X, Y in [(400, 600), (650, 620)]:
        page.mouse.click(x0 + X, y0 + Y)
        settle(page)
    assert len(running.plan()["plans"]) == 2


def test_save_and_load_round_trip(page: Any, running: Running, tmp_path: Path) -> None:
    original = running.plan()
    with page.expect_download() as info:
        page.click("#download")
    saved = tmp_path / "saved.json"
    info.value.save_as(saved)
    assert tag_to_dict(load_plan(saved)) == original
    page.click("#clear")
    settle(page)
    page.wait_for_function("window.studio.state.tag === null")
    page.set_input_files("#open", str(saved))
    page.wait_for_function("window.studio.state.tag !== null")
    assert running.plan() == original


def test_model_switch_and_globals(page: Any, running: Running) -> None:
    page.select_option("#model", "sigma")
    settle(page)
    page.wait_for_function("window.studio.state.design.model === 'sigma'")
    plan = running.plan()
    assert plan["model"] == "sigma" and "phi" in strokes(plan)[0]
    assert page.locator("circle.phi").count() == 3  # ΣΛ*: one φ handle per stroke
    page.fill("#sigma", "0.5")
    page.press("#sigma", "Enter")
    settle(page)
    page.wait_for_function("window.studio.state.design.sigma === 0.5")
    assert all(s["sigma"] == 0.5 for s in strokes(running.plan()))


def test_draw_on_the_simulated_plotter(page: Any, running: Running) -> None:
    page.select_option("#device", "grbl")
    page.click("#draw")
    page.wait_for_function(
        "document.getElementById('draw-status').textContent.startsWith('done')", timeout=180_000
    )
    status = running.client.get("/api/draw").json()
    assert status["state"] == "done" and status["done"] == status["total"] > 0
    folder = Path(status["folder"])
    assert folder.parent == running.runs
    for name in ("plan.json", "motion.csv", "program.gcode", "executed.csv", "report.json"):
        assert (folder / name).is_file(), name
    report = json.loads((folder / "report.json").read_text())
    assert report["completed"] and report["device"] == "grbl" and report["simulated"]
    assert tag_to_dict(load_plan(folder / "plan.json")) == running.plan()
    assert page.evaluate("window.studio.stats.drawn.executed") >= 1
    assert page.evaluate("window.studio.stats.livePoints") > 0  # the trace came in as it ran


def test_draw_on_the_simulated_axidraw(page: Any, running: Running) -> None:
    assert "AxiDraw" in page.locator("#device option[value=axidraw]").inner_text()
    page.select_option("#device", "axidraw")
    page.click("#draw")
    page.wait_for_function(
        "document.getElementById('draw-status').textContent.startsWith('done')", timeout=180_000
    )
    status = running.client.get("/api/draw").json()
    assert status["state"] == "done" and status["device"] == "axidraw"
    assert status["done"] == status["total"] > 0
    folder = Path(status["folder"])
    assert folder.parent == running.runs and "-axidraw-" in folder.name
    for name in ("plan.json", "motion.csv", "moves.txt", "executed.csv", "report.json"):
        assert (folder / name).is_file(), name
    report = json.loads((folder / "report.json").read_text())
    assert report["completed"] and report["device"] == "axidraw" and report["simulated"]
    assert report["unit"] == "move" and report["executed"] == report["total"]
    assert tag_to_dict(load_plan(folder / "plan.json")) == running.plan()
    assert page.evaluate("window.studio.stats.drawn.executed") >= 1
    assert page.evaluate("window.studio.stats.livePoints") > 0  # the trace came in as it ran


def test_draw_on_the_simulated_openmanipulator_x(page: Any, running: Running) -> None:
    option = "#device option[value='dynamixel:openmanipulator-x']"
    assert "OpenManipulator-X" in page.locator(option).inner_text()
    page.select_option("#device", "dynamixel:openmanipulator-x")
    page.click("#draw")
    page.wait_for_function(
        "document.getElementById('draw-status').textContent.startsWith('done')", timeout=180_000
    )
    status = running.client.get("/api/draw").json()
    assert status["state"] == "done" and status["device"] == "dynamixel"
    assert status["profile"] == "openmanipulator-x" and status["done"] == status["total"] > 0
    folder = Path(status["folder"])
    assert folder.parent == running.runs and "-openmanipulator-x-" in folder.name
    report = json.loads((folder / "report.json").read_text())
    assert report["completed"] and report["simulated"]
    assert report["executed_source"].startswith("physics simulator")
    assert page.evaluate("window.studio.stats.livePoints") > 0  # the trace came in as it ran


def test_another_origin_cannot_drive_the_studio(browser: Any, running: Running) -> None:
    running.load(PLAN)
    version = running.state()["version"]
    context = browser.new_context()
    try:
        other = context.new_page()
        other.goto("data:text/html,<p>another page</p>")
        url = f"{running.base}/api/plan?token={running.studio.token}"
        body = json.dumps({"ops": [{"op": "clear"}]})
        other.evaluate(
            "([url, body]) => fetch(url, {method: 'POST', mode: 'no-cors', body})"
            ".catch(() => null)",
            [url, body],
        )
        other.evaluate(
            "(url) => fetch(url.replace('/api/plan', '/api/draw'), {method: 'POST',"
            " mode: 'no-cors', body: '{}'}).catch(() => null)",
            url,
        )
    finally:
        context.close()
    assert running.state()["version"] == version
    assert running.client.get("/api/draw").json()["state"] in ("idle", "done")
    assert running.plan() == PLAN


def test_variations_side_by_side_and_adopt_one(page: Any, running: Running) -> None:
    page.click("#vary")
    page.wait_for_function("document.querySelectorAll('#variants figure').length === 4")
    page.locator("#variants figure").nth(2).locator("button").click()
    page.wait_for_function("document.getElementById('status').textContent.includes('#3')")
    adopted = running.plan()
    assert adopted != PLAN
    assert len(adopted["plans"][0]["targets"]) == len(PLAN["plans"][0]["targets"])
    page.click("#undo")
    page.wait_for_function("window.studio.state.can_redo")
    assert running.plan() == PLAN


def test_play_moves_the_pen_along_the_trajectory(page: Any, running: Running) -> None:
    # Every position the pen takes is recorded in the page, so a busy host that
    # draws few frames (or ends the animation early) still shows the pen moving.
    page.evaluate(
        """() => {
        window.penTrail = [];
        new MutationObserver((changes) => {
            for (const c of changes)
                if (c.target.id === 'pen') window.penTrail.push(+c.target.getAttribute('cx'));
        }).observe(document.body, {subtree: true, attributes: true, attributeFilter: ['cx']});
    }"""
    )
    page.click("#play")
    page.wait_for_function("new Set(window.penTrail).size >= 3", timeout=20_000)
    # The brush preview is the server's render_array picture.
    page.wait_for_function("document.getElementById('brush').src.startsWith('blob:')")
    assert page.evaluate("document.getElementById('brush').naturalWidth") == 460


def test_shift_drag_moves_the_whole_plan(page: Any, running: Running) -> None:
    motion = running.state()["motion"]
    i = len(motion["x"]) // 2
    start = to_screen(page, [motion["x"][i], motion["y"][i]])
    start = (round(start[0]), round(start[1]))
    page.keyboard.down("Shift")
    drag(page, start, (start[0] + 30, start[1] + 20))
    page.keyboard.up("Shift")
    s = page.evaluate("window.studio.view.s")
    moved = running.plan()["plans"][0]
    expected = [[x + 30 / s, y - 20 / s] for x, y in PLAN["plans"][0]["targets"]]
    assert np.allclose(moved["targets"], expected, atol=1e-6)
    assert moved["strokes"] == PLAN["plans"][0]["strokes"]


def test_the_page_works_under_its_own_content_security_policy(
    browser: Any, running: Running
) -> None:
    running.load(PLAN)
    context = browser.new_context(viewport={"width": 1400, "height": 860})  # CSP enforced
    try:
        page = context.new_page()
        problems: list[str] = []
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.on(
            "console",
            lambda m: problems.append(m.text) if "Content Security Policy" in m.text else None,
        )
        page.goto(running.url)
        page.wait_for_selector("circle.target")
        start = page.locator('circle.target[data-plan="0"][data-index="1"]').bounding_box()
        x, y = start["x"] + start["width"] / 2, start["y"] + start["height"] / 2
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 20, y, steps=4)
        page.mouse.up()
        deadline = time.monotonic() + 30
        while running.plan() == PLAN and time.monotonic() < deadline:
            time.sleep(0.05)
        assert running.plan() != PLAN  # the drag went through the WebSocket or the API
        page.wait_for_selector("#brush[src^='blob:']")
        assert not problems, problems
    finally:
        context.close()
