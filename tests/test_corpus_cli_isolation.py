"""A bad file in a corpus run through the CLI leaves the other files' results whole (issue 34):
each good file's plan and summary row are what fitting it alone gives."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from tagbot.cli import main

DATA = Path(__file__).parent / "inputs" / "data"


def _rows(path: Path) -> dict[str, dict[str, str]]:
    with open(path, newline="") as f:
        return {Path(r["input"]).name: r for r in csv.DictReader(f)}


@pytest.mark.parametrize("bad", ["<gml><tag><drawing><stroke><pt><x>oops", ""])
def test_one_bad_file_leaves_the_others_whole(tmp_path: Path, capsys, bad: str) -> None:
    folder = tmp_path / "tags"
    folder.mkdir()
    shutil.copy(DATA / "spec10.gml", folder / "a.gml")
    (folder / "b.gml").write_text(bad)
    shutil.copy(DATA / "sideways.gml", folder / "c.gml")
    out = tmp_path / "plans"
    assert main(["fit", str(folder), "-o", str(out), "--jobs", "1"]) == 1
    err = capsys.readouterr().err
    assert f"tagbot: error: {folder / 'b.gml'}: " in err
    assert "2 of 3 file(s) done, 1 failed" in err
    rows = _rows(out / "summary.csv")
    assert rows["b.gml"]["status"] == "error" and not (out / "b.json").exists()
    for name in ("a.gml", "c.gml"):
        alone = tmp_path / f"alone-{name}"
        alone.mkdir()
        assert main(["fit", str(folder / name), "-o", str(alone / "plan.json")]) == 0
        capsys.readouterr()
        row = rows[name]
        assert row["status"] == "ok" and row["error"] == ""
        together = json.loads(Path(row["output"]).read_text())
        assert together["plans"] == json.loads((alone / "plan.json").read_text())["plans"]
