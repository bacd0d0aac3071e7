"""The studio's JSON API on a real server: security, validation, edits, exports, draws."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from tagbot.cli import main
from tagbot.io.planfile import load_plan, save_plan, tag_from_dict, tag_to_dict
from tagbot.model import random_plan, sequence
from tagbot.studio.server import Studio
from tests.studio.conftest import PLAN, Running


def patch(running: Running, ops: list[dict[str, Any]], group: str | None = None) -> httpx.Response:
    return running.client.patch("/api/plan", json={"ops": ops, "group": group})


def stroke(plan: dict[str, Any], j: int) -> dict[str, float]:
    return plan["plans"][0]["strokes"][j]  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- security


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("GET", "/"),
        ("GET", "/api/state"),
        ("PATCH", "/api/plan"),
        ("POST", "/api/undo"),
        ("POST", "/api/draw"),
        ("GET", "/api/export?format=gcode"),
    ],
)
def test_requests_without_the_token_are_refused(running: Running, method: str, path: str) -> None:
    for headers in ({}, {"X-Tagbot-Token": running.studio.token + "x"}):
        response = httpx.request(method, running.base + path, headers=headers, json={"ops": []})
        assert response.status_code == 403
        assert "token" in response.json()["error"]
    assert running.client.get("/api/draw").json()["state"] in ("idle", "done", "stopped")


def test_other_origins_and_hosts_are_refused(running: Running) -> None:
    version = running.state()["version"]
    for headers in (
        {"Origin": "http://evil.example"},
        {"Origin": "null"},
        {"Origin": f"http://127.0.0.1:{running.server.port + 1}"},
        {"Host": f"evil.example:{running.server.port}"},  # DNS rebinding
        {"Host": "127.0.0.1"},
    ):
        response = running.client.patch(
            "/api/plan", headers=headers, json={"ops": [{"op": "clear"}]}
        )
        assert response.status_code == 403, headers
        assert running.client.post("/api/draw", headers=headers, json={}).status_code == 403
    assert running.state()["version"] == version
    # The studio's own origin, and localhost, are fine.
    ok = running.client.get("/api/state", headers={"Origin": running.base})
    assert ok.status_code == 200
    local = {"Host": f"localhost:{running.server.port}"}
    assert running.client.get("/api/state", headers=local).status_code == 200


def test_websocket_needs_the_token_and_the_origin(running: Running) -> None:
    url = f"ws://127.0.0.1:{running.server.port}/ws"
    with connect(f"{url}?token={running.studio.token}", origin=running.base) as ws:  # type: ignore[arg-type]
        assert json.loads(ws.recv(timeout=10))["type"] == "hello"
    for address, origin in (
        (url, running.base),
        (f"{url}?token={running.studio.token}", "http://evil.example"),
    ):
        with pytest.raises(InvalidStatus), connect(address, origin=origin):  # type: ignore[arg-type]
            pass


def test_static_files_need_no_token_but_the_page_does(running: Running) -> None:
    script = httpx.get(f"{running.base}/static/studio.js")
    assert script.status_code == 200 and "text/javascript" in script.headers["content-type"]
    assert httpx.get(f"{running.base}/static/nothing.js").status_code == 404
    page = httpx.get(running.url)
    assert (
        page.status_code == 200
        and "frame-ancestors 'none'" in page.headers["content-security-policy"]
    )


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b'{"ops": [{"op": "set", "plan": 0, "stroke": 0, "field": "dt", "value": NaN}]}', "NaN"),
        (b'{"ops": [{"op": "move_target", "plan": 0, "index": 1, "to": [1e999, 0]}]}', "finite"),
        (b'{"ops": [{"op": "move_target", "plan": 3, "index": 1, "to": [1, 0]}]}', "ops[0].plan"),
        (b'{"ops": [{"op": "move_target", "plan": 0, "index": 9, "to": [1, 0]}]}', "ops[0].index"),
        (b'{"ops": [{"op": "spin"}]}', "ops[0].op: unknown 'spin'"),
        (
            b'{"ops": [{"op": "set", "plan": 0, "stroke": 0, "field": "sigma", "value": -1}]}',
            "value",
        ),
        (b'{"ops": [{"op": "move_target", "plan": 0, "index": 1, "to": [0, 0]}]}', "coincides"),
        (b'{"ops": [{"op": "globals", "dt_min": 0.5, "dt_max": 0.2}]}', "dt_max"),
        (b'{"ops": "clear"}', "ops: expected a list"),
        (b"[1, 2]", "expected a JSON object"),
        (b"{", "not JSON"),
    ],
)
def test_bad_edits_are_refused_with_a_clear_message(
    running: Running, body: bytes, message: str
) -> None:
    running.load(PLAN)
    response = running.client.patch("/api/plan", content=body)
    assert response.status_code == 400
    error = response.json()["error"]
    assert message in error and "\n" not in error
    assert running.plan() == PLAN  # nothing changed


def test_bodies_and_gestures_are_bounded(running: Running) -> None:
    huge = b'{"ops": [' + b'{"op": "clear"},' * 200_000 + b'{"op": "clear"}]}'
    assert running.client.patch("/api/plan", content=huge).status_code == 413
    many = {"ops": [{"op": "clear"}] * 501}
    assert "at most 500" in running.client.patch("/api/plan", json=many).json()["error"]
    points = [[i * 0.01, 0.0, i * 0.001] for i in range(20_001)]
    response = running.client.post("/api/gesture", json={"points": points})
    assert response.status_code == 400 and "at most 20000" in response.json()["error"]
    backwards = [[0, 0, 0.2], [10, 0, 0.1], [20, 5, 0.3]]
    response = running.client.post("/api/gesture", json={"points": backwards})
    assert response.json()["error"] == "points: times must not decrease"
    response = running.client.get("/api/brush.png?width=100000")
    assert response.status_code == 400 and "width" in response.json()["error"]


# --------------------------------------------------------------------------- edits


def test_edits_of_one_group_are_one_undo_step(running: Running) -> None:
    running.load(PLAN)
    for x in (10.0, 20.0, 30.0):
        assert patch(
            running, [{"op": "move_target", "plan": 0, "index": 0, "to": [x, 0.0]}], "g"
        ).is_success
    assert running.plan()["plans"][0]["targets"][0] == [30.0, 0.0]
    state = running.client.post("/api/undo").json()
    assert state["tag"] == PLAN and state["can_redo"]
    assert running.client.post("/api/redo").json()["tag"]["plans"][0]["targets"][0] == [30.0, 0.0]


def test_insert_and_delete_targets(running: Running) -> None:
    running.load(PLAN)
    assert patch(running, [{"op": "insert", "plan": 0, "index": 2, "at": [70.0, 40.0]}]).is_success
    plan = running.plan()
    assert plan["plans"][0]["targets"][2] == [70.0, 40.0]
    assert len(plan["plans"][0]["strokes"]) == 4
    assert stroke(plan, 1)["dt"] == 0.2 and stroke(plan, 1)["phi1"] == 0.0
    assert patch(running, [{"op": "delete", "plan": 0, "index": 2}]).is_success
    plan = running.plan()
    assert plan["plans"][0]["targets"] == PLAN["plans"][0]["targets"]
    assert stroke(plan, 2) == PLAN["plans"][0]["strokes"][2]
    # Deleting the first target makes the next stroke start at once.
    assert patch(running, [{"op": "delete", "plan": 0, "index": 0}]).is_success
    assert stroke(running.plan(), 0)["dt"] == 0.0


def test_move_a_whole_plan(running: Running) -> None:
    running.load(PLAN)
    assert patch(running, [{"op": "move_plan", "plan": 0, "by": [5.0, -2.0]}]).is_success
    moved = running.plan()["plans"][0]
    assert moved["targets"] == [[x + 5.0, y - 2.0] for x, y in PLAN["plans"][0]["targets"]]
    assert moved["strokes"] == PLAN["plans"][0]["strokes"]


def test_globals_keep_each_dt_in_its_place_and_set_mu_sigma(running: Running) -> None:
    running.load(PLAN)
    design = running.state()["design"]
    lo, hi = design["dt_min"], design["dt_max"]
    fraction = (0.25 - lo) / (hi - lo)
    ops = [{"op": "globals", "dt_min": 0.05, "dt_max": 0.45, "mu": -1.5, "sigma": 0.3}]
    assert patch(running, ops).is_success
    plan = running.plan()
    assert stroke(plan, 2)["dt"] == pytest.approx(0.05 + fraction * 0.4)
    assert stroke(plan, 0)["dt"] == 0.0
    assert {(s["mu"], s["sigma"]) for s in plan["plans"][0]["strokes"]} == {(-1.5, 0.3)}


def test_switching_model_keeps_the_mean_deviation(running: Running) -> None:
    running.load(PLAN)
    assert patch(running, [{"op": "model", "model": "sigma"}]).is_success
    plan = running.plan()
    assert plan["model"] == "sigma"
    assert [s["phi"] for s in plan["plans"][0]["strokes"]] == pytest.approx([-0.25, 0.45, -0.05])
    assert patch(
        running, [{"op": "aim", "plan": 0, "stroke": 0, "end": 2, "toward": [60, -20]}]
    ).is_success
    assert patch(running, [{"op": "model", "model": "gamma"}]).is_success
    s = stroke(running.plan(), 0)
    assert s["phi1"] == -s["phi2"]


def test_several_plans_with_pen_lifts(running: Running) -> None:
    running.load(PLAN)
    ops = [
        {"op": "new_plan", "at": [0.0, -50.0]},
        {"op": "append", "plan": 1, "at": [50.0, -60.0]},
        {"op": "append", "plan": 1, "at": [90.0, -40.0]},
        {"op": "lift", "plan": 1, "seconds": 0.5},
    ]
    assert patch(running, ops).is_success
    tag = tag_from_dict(running.plan())
    assert len(tag.plans) == 2
    assert tag.plans[1].start - tag.plans[0].end(tag.size) == pytest.approx(0.5)
    state = running.state()
    assert 0 in state["motion"]["pen"]  # the lift shows as pen-up samples


def test_variations_are_reproducible_and_adoptable(running: Running) -> None:
    running.load(PLAN)
    first = running.client.post("/api/variations", json={"count": 3, "seed": 5}).json()
    second = running.client.post("/api/variations", json={"count": 3, "seed": 5}).json()
    assert first == second and len(first["variants"]) == 3
    assert first["variants"][0]["tag"] != PLAN
    assert running.client.post("/api/variations/adopt", json={"index": 1}).is_success
    assert running.plan() == first["variants"][1]["tag"]
    assert running.client.post("/api/undo").json()["tag"] == PLAN


def test_open_a_trace_file_fits_it(running: Running) -> None:
    s = np.linspace(0, 1, 200)
    rows = "\n".join(f"{60 * u:.4f},{20 * np.sin(6 * u):.4f}" for u in s)
    response = running.client.post("/api/open?name=wave.csv", content=f"x,y\n{rows}\n".encode())
    assert response.status_code == 200, response.text
    state = response.json()
    assert state["tag"] is not None and len(state["design"]["gestures"]) == 1
    bad = running.client.post("/api/open?name=junk.bin", content=b"%PDF-1.4 nothing")
    assert bad.status_code == 400 and bad.json()["error"].startswith("junk.bin: ")


# --------------------------------------------------------------------------- keep and export


def test_exports_are_the_files_the_cli_writes(running: Running, tmp_path: Path) -> None:
    running.load(PLAN)
    plan = tmp_path / "plan.json"
    save_plan(tag_from_dict(PLAN), plan)
    downloaded = running.client.get("/api/plan?download=1")
    assert downloaded.content == plan.read_bytes()
    assert "attachment" in downloaded.headers["content-disposition"]
    assert main(["gcode", str(plan), "-o", str(tmp_path / "tag.gcode")]) == 0
    gcode = running.client.get("/api/export?format=gcode")
    assert gcode.content == (tmp_path / "tag.gcode").read_bytes()
    assert main(["render", str(plan), "-o", str(tmp_path / "tag.svg")]) == 0
    svg = running.client.get("/api/export?format=svg")
    assert svg.content == (tmp_path / "tag.svg").read_bytes()
    png = running.client.get("/api/export?format=png&drips=1&seed=3")
    assert png.content.startswith(b"\x89PNG")
    assert running.client.get("/api/export?format=bmp").json()["error"].startswith("format:")


def test_save_without_a_plan_file_says_so(running: Running) -> None:
    response = running.client.post("/api/save")
    assert response.status_code == 409 and "download" in response.json()["error"]


def test_autosave_brings_the_design_back(running: Running) -> None:
    running.load(PLAN)
    assert patch(
        running, [{"op": "move_target", "plan": 0, "index": 3, "to": [150.0, 20.0]}]
    ).is_success
    path = running.studio.autosave
    assert path is not None
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        if path.exists() and "150.0" in path.read_text():
            break
        time.sleep(0.05)
    again = Studio(autosave=path)
    try:
        assert again.design["plans"][0]["targets"][3] == [150.0, 20.0]
    finally:
        again.shutdown()


# --------------------------------------------------------------------------- draw


def wait_for(running: Running, states: tuple[str, ...], timeout: float = 120) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = running.client.get("/api/draw").json()
        if status["state"] in states:
            return status  # type: ignore[no-any-return]
        time.sleep(0.05)
    raise AssertionError(f"draw never reached {states}: {status}")


def test_draw_pause_resume_and_stop(running: Running) -> None:
    rng = np.random.default_rng(3)
    tag = sequence([random_plan(rng, targets=(11, 11)) for _ in range(3)], 0.3)
    running.load(tag_to_dict(tag))
    assert running.client.post("/api/draw/pause").status_code == 409
    started = running.client.post("/api/draw", json={"device": "grbl"})
    assert started.status_code == 202
    assert running.client.post("/api/draw", json={"device": "grbl"}).status_code == 409
    wait_for(running, ("running",))
    assert running.client.post("/api/draw/pause").json()["state"] == "paused"
    time.sleep(0.3)
    held = running.client.get("/api/draw").json()["done"]
    time.sleep(0.5)
    assert running.client.get("/api/draw").json()["done"] == held  # a feed hold: no progress
    assert running.client.post("/api/draw/resume").json()["state"] == "running"
    assert running.client.post("/api/draw/stop").json()["state"] == "stopping"
    status = wait_for(running, ("stopped", "done", "failed"))
    assert status["state"] == "stopped", status
    report = json.loads((Path(status["folder"]) / "report.json").read_text())
    assert report["completed"] is False and "interrupted" in report["error"]
    assert load_plan(Path(status["folder"]) / "plan.json").n_strokes == 30


def test_draw_refuses_an_unknown_device(running: Running) -> None:
    response = running.client.post("/api/draw", json={"device": "laser"})
    assert response.status_code == 400 and "device" in response.json()["error"]


def test_draw_on_the_simulated_openmanipulator_x(running: Running) -> None:
    running.load(PLAN)
    started = running.client.post(
        "/api/draw", json={"device": "dynamixel", "profile": "openmanipulator-x"}
    )
    assert started.status_code == 202 and started.json()["profile"] == "openmanipulator-x"
    status = wait_for(running, ("done", "stopped", "failed"))
    assert status["state"] == "done", status
    folder = Path(status["folder"])
    assert "-openmanipulator-x-" in folder.name
    report = json.loads((folder / "report.json").read_text())
    assert report["completed"] and report["simulated"] and report["device"] == "dynamixel"
    assert report["executed_source"].startswith("physics simulator")  # the serial arm's
    header = (folder / "joints.csv").read_text().splitlines()[0]
    assert header == "t,joint1,joint2,joint3,joint4"
    assert status["done"] == status["total"] == report["total"]


def test_draw_on_a_serial_arm_named_on_the_command_line(running: Running) -> None:
    from sim.dynamixel import attach_chain, detach_chain
    from tagbot.arm.serial.machine import simulated_arm
    from tagbot.arm.serial.profile import load_serial_profile

    chain, physics = simulated_arm(load_serial_profile("koch-v1.1"))
    url = attach_chain(chain, "studio_koch")
    running.load(PLAN)
    running.studio.machine_port = url  # as `tagbot studio --machine-port URL` sets it
    try:
        body = {"device": "dynamixel", "profile": "koch-v1.1"}
        assert running.client.post("/api/draw", json=body).status_code == 202
        status = wait_for(running, ("done", "stopped", "failed"))
    finally:
        running.studio.machine_port = None
        detach_chain("studio_koch")
    assert status["state"] == "done", status
    report = json.loads((Path(status["folder"]) / "report.json").read_text())
    assert report["port"] == url and report["simulated"] is False and report["completed"]
    header = (Path(status["folder"]) / "joints.csv").read_text().splitlines()[0]
    assert header == "t,shoulder_pan,shoulder_lift,elbow_flex,wrist_flex,wrist_roll"
    assert physics.pen_trace()[:, 3].any()  # the arm behind the URL inked the paper


def test_draw_refuses_a_profile_that_is_no_serial_arm(running: Running) -> None:
    for body in (
        {"device": "grbl", "profile": "openmanipulator-x"},
        {"device": "dynamixel", "profile": "default"},
    ):
        response = running.client.post("/api/draw", json=body)
        assert response.status_code == 400
        assert response.json()["error"].startswith("profile: ")
    assert running.client.get("/api/draw").json()["state"] != "preparing"


def test_draw_on_the_port_named_on_the_command_line(running: Running) -> None:
    from sim.grbl import SimulatedGrbl
    from sim.grbl.transport import attach_device
    from tagbot.plotter.machine import simulated_pen
    from tagbot.plotter.profile import device_settings, load_profile

    profile = load_profile()
    device = SimulatedGrbl(device_settings(profile), **simulated_pen(profile))
    url = attach_device(device, "studio_port")
    running.load(PLAN)
    running.studio.machine_port = url  # as `tagbot studio --machine-port URL` sets it
    try:
        assert running.state()["machine_port"] == url
        assert running.client.post("/api/draw", json={"device": "grbl"}).status_code == 202
        status = wait_for(running, ("done", "stopped", "failed"))
    finally:
        running.studio.machine_port = None
    assert status["state"] == "done", status
    report = json.loads((Path(status["folder"]) / "report.json").read_text())
    assert report["port"] == url and report["simulated"] is False and report["completed"]
    assert device.lines_received > 0


def test_draw_on_an_axidraw_named_on_the_command_line(running: Running) -> None:
    from sim.ebb.device import SimulatedEBB
    from sim.ebb.transport import attach_device

    device = SimulatedEBB()
    url = attach_device(device, "studio_axidraw")
    running.load(PLAN)
    running.studio.machine_port = url  # as `tagbot studio --machine-port URL` sets it
    try:
        assert running.client.post("/api/draw", json={"device": "axidraw"}).status_code == 202
        status = wait_for(running, ("done", "stopped", "failed"))
    finally:
        running.studio.machine_port = None
    assert status["state"] == "done", status
    report = json.loads((Path(status["folder"]) / "report.json").read_text())
    assert report["device"] == "axidraw" and report["port"] == url
    assert report["simulated"] is False and report["completed"]
    moves = (Path(status["folder"]) / "moves.txt").read_bytes().splitlines()
    assert len(moves) == report["total"]
    assert device.recorder.moves()  # the board behind the URL drew it


def test_axidraw_pause_holds_and_stop_is_safe(running: Running) -> None:
    rng = np.random.default_rng(5)
    tag = sequence([random_plan(rng, targets=(11, 11)) for _ in range(3)], 0.3)
    running.load(tag_to_dict(tag))
    assert running.client.post("/api/draw", json={"device": "axidraw"}).status_code == 202
    wait_for(running, ("running",))
    assert running.client.post("/api/draw/pause").json()["state"] == "paused"
    time.sleep(0.5)  # the board drains its FIFO (a few moves) and the pen lifts
    held = running.client.get("/api/draw").json()["done"]
    time.sleep(0.5)
    assert running.client.get("/api/draw").json()["done"] == held  # nothing more executes
    assert running.client.post("/api/draw/resume").json()["state"] == "running"
    assert running.client.post("/api/draw/stop").json()["state"] == "stopping"
    status = wait_for(running, ("stopped", "done", "failed"))
    assert status["state"] == "stopped", status
    report = json.loads((Path(status["folder"]) / "report.json").read_text())
    assert report["completed"] is False and "interrupted" in report["error"]
    assert report["unit"] == "move" and report["resume_from"] is not None


def test_gif_export_is_an_animation(running: Running) -> None:
    running.load(PLAN)
    gif = running.client.get("/api/export?format=gif")
    assert gif.status_code == 200 and gif.content.startswith(b"GIF89a")
    assert 'filename="' in gif.headers["content-disposition"]
