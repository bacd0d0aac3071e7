"""``tagbot studio`` as a command: serves, refuses bad options in one line, stops on Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import httpx

from tagbot.cli import main
from tagbot.io.planfile import load_plan, save_plan, tag_from_dict
from tagbot.studio.server import Studio, StudioServer
from tests.studio.conftest import PLAN


def test_bad_machine_port_is_one_line(capsys: object, tmp_path: Path) -> None:
    assert main(["studio", "--no-browser", "--machine-port", "nope://x"]) == 2
    err = capsys.readouterr().err  # type: ignore[attr-defined]
    assert (
        err.startswith("tagbot: error: --machine-port nope://x: unknown URL scheme")
        and err.count("\n") == 1
    )


def test_studio_serves_a_plan_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    plan = tmp_path / "tag.json"
    save_plan(tag_from_dict(PLAN), plan)
    autosave = tmp_path / "state" / "studio.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen(
        [
            *(sys.executable, "-m", "tagbot", "studio", str(plan), "--no-browser"),
            *("--autosave", str(autosave), "--runs", str(tmp_path / "runs")),
        ],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert process.stderr is not None
        seen = []
        match = None
        while match is None and len(seen) < 50:
            line = process.stderr.readline()
            if not line:
                break
            seen.append(line)
            match = re.search(r"(http://127\.0\.0\.1:(\d+)/\?token=(\S+))", line)
        assert match, "".join(seen)
        base = f"http://127.0.0.1:{match[2]}"
        headers = {"X-Tagbot-Token": match[3]}
        state = httpx.get(f"{base}/api/state", headers=headers, timeout=60).json()
        assert state["tag"] == PLAN and state["save_path"] == str(plan)
        ops = {"ops": [{"op": "move_target", "plan": 0, "index": 0, "to": [1.0, 2.0]}]}
        assert httpx.patch(f"{base}/api/plan", headers=headers, json=ops, timeout=60).is_success
        assert httpx.post(f"{base}/api/save", headers=headers, timeout=60).is_success
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=60) == 0
        rest = process.stderr.read()
        assert "studio stopped" in rest and "Traceback" not in rest
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        if process.stderr is not None:
            process.stderr.close()
    assert load_plan(plan).plans[0].targets[0].tolist() == [1.0, 2.0]
    assert "[1.0, 2.0]" in autosave.read_text()  # written on the way out


def test_a_browser_opened_before_the_server_runs_is_served(tmp_path: Path) -> None:
    # The URL is printed and the browser opened before uvicorn starts: the port already listens.
    studio = Studio(tag=tag_from_dict(PLAN), autosave=tmp_path / "a.json", runs=tmp_path / "runs")
    server = StudioServer(studio)
    early = socket.create_connection(("127.0.0.1", server.port), timeout=10)
    try:
        server.start()
        host = f"127.0.0.1:{server.port}"
        early.sendall(f"GET /static/studio.js HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
        assert early.recv(64).startswith(b"HTTP/1.1 200 ")
    finally:
        early.close()
        server.stop()
