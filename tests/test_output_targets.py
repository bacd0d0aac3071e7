"""``-o`` names a file: a device, a FIFO or a socket is refused before any work, by every
command that writes one (the atomic write would otherwise replace the node with a file)."""

from __future__ import annotations

import os
import socket
from importlib import resources

import pytest

import tagbot.gesture
from tagbot.cli import main
from tagbot.errors import OutputError
from tagbot.io.output import check_output_file

TRACES = str(resources.files("tagbot") / "examples" / "dusttag-142.json")


def _fifo(tmp_path, name: str = "pipe") -> str:
    path = tmp_path / name
    os.mkfifo(path)
    return str(path)


@pytest.mark.parametrize("command", ["fit", "gcode", "render", "plot"])
@pytest.mark.parametrize("target", ["fifo", "/dev/null"])
def test_an_output_that_is_not_a_file_is_refused_before_any_work(
    command, target, tmp_path, capsys, monkeypatch
):
    def no_fit(*args, **kwargs):
        raise AssertionError("the work started")

    monkeypatch.setattr(tagbot.gesture, "fit", no_fit)
    picture = command in ("render", "plot")
    path = _fifo(tmp_path, "out.png" if picture else "out.json") if target == "fifo" else target
    before = os.stat(path)
    code = main([command, TRACES, "-o", path])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("tagbot: error: ") and err.count("\n") == 1, err
    if picture and target == "/dev/null":  # refused first for having no picture suffix
        assert f"{path}: " in err and "not a regular file" not in err
    else:
        kind = "a FIFO" if target == "fifo" else "a character device"
        assert f"{path}: is {kind}, not a regular file" in err
    after = os.stat(path)
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)


def test_a_socket_is_refused_and_files_and_new_paths_pass(tmp_path):
    path = tmp_path / "s"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(path))
        with pytest.raises(OutputError, match="is a socket, not a regular file"):
            check_output_file(path)
    existing = tmp_path / "old.json"
    existing.write_text("{}")
    check_output_file(existing)
    check_output_file(tmp_path / "new.json")
    check_output_file("-")
