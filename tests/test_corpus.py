"""Corpus mode: many inputs fitted or rendered in worker processes or on a Dask cluster, one
summary row per file, one bad file never stopping the rest."""

from __future__ import annotations

import csv
import shutil
from importlib import resources
from pathlib import Path

import pytest

from tagbot.cli import main
from tagbot.corpus import FileJob, expand_inputs, fit_file, map_files, output_paths

EXAMPLE = resources.files("tagbot") / "examples" / "dusttag-142.json"
DATA = Path(__file__).parent / "inputs" / "data"


@pytest.fixture
def corpus(tmp_path: Path) -> Path:
    """Three good trace files (one in a subfolder) and one that is not a trace file."""
    folder = tmp_path / "tags"
    (folder / "more").mkdir(parents=True)
    shutil.copy(EXAMPLE, folder / "dust.json")
    shutil.copy(DATA / "spec10.gml", folder / "spec.gml")
    shutil.copy(DATA / "sideways.gml", folder / "more" / "sideways.gml")
    (folder / "broken.gml").write_text("<gml><tag><drawing><stroke><pt><x>oops")
    (folder / "notes.md").write_text("not an input: wrong suffix, never read")
    return folder


def summary(path: Path) -> dict[str, dict[str, str]]:
    with open(path, newline="") as f:
        return {Path(r["input"]).name: r for r in csv.DictReader(f)}


def test_a_folder_is_fitted_and_a_bad_file_does_not_stop_the_rest(corpus, tmp_path, capsys):
    out = tmp_path / "plans"
    code = main(["fit", str(corpus), "-o", str(out), "--jobs", "2"])
    err = capsys.readouterr().err
    assert code == 1  # one file failed
    rows = summary(out / "summary.csv")
    assert sorted(rows) == ["broken.gml", "dust.json", "sideways.gml", "spec.gml"]
    assert rows["broken.gml"]["status"] == "error"
    assert rows["broken.gml"]["error"].startswith(str(corpus / "broken.gml") + ": ")
    assert f"tagbot: error: {corpus / 'broken.gml'}: " in err
    for name in ("dust.json", "spec.gml", "sideways.gml"):
        row = rows[name]
        assert row["status"] == "ok" and Path(row["output"]).is_file()
        assert int(row["strokes"]) > 0 and float(row["shape_error_mean"]) < 0.01
    assert "3 of 4 file(s) done, 1 failed" in err


def test_workers_give_the_same_plans_as_one_process(corpus, tmp_path):
    (corpus / "broken.gml").unlink()
    one, two = tmp_path / "one", tmp_path / "two"
    assert main(["fit", str(corpus), "-o", str(one), "--jobs", "1", "--no-report"]) == 0
    assert main(["fit", str(corpus), "-o", str(two), "--jobs", "2", "--no-report"]) == 0
    plans = sorted(p.name for p in one.glob("*.json"))
    assert plans == ["dust.json", "sideways.json", "spec.json"]
    for name in plans:
        assert (one / name).read_bytes() == (two / name).read_bytes()
    assert "shape_error_mean" not in summary(one / "summary.csv")["dust.json"]


def test_globs_and_several_files_are_expanded_in_order(corpus):
    found = expand_inputs([str(corpus / "**" / "*.gml"), str(corpus / "dust.json")])
    names = [Path(p).name for p in found]
    assert names == ["broken.gml", "sideways.gml", "spec.gml", "dust.json"]
    assert output_paths(["a/x.gml", "b/x.json", "c/y.svg"], "out", ".png") == [
        str(Path("out/x.png")),
        str(Path("out/x-2.png")),
        str(Path("out/y.png")),
    ]


def test_nothing_is_overwritten_without_force(corpus, tmp_path, capsys):
    (corpus / "broken.gml").unlink()
    out = tmp_path / "plans"
    assert main(["fit", str(corpus), "-o", str(out), "--no-report"]) == 0
    capsys.readouterr()
    assert main(["fit", str(corpus), "-o", str(out), "--no-report"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tagbot: error: ") and "exists" in err and "--force" in err
    assert main(["fit", str(corpus), "-o", str(out), "--no-report", "--force"]) == 0


def test_many_inputs_need_a_folder_and_a_missing_input_is_named(corpus, tmp_path, capsys):
    assert main(["fit", str(corpus)]) == 2
    assert "-o DIR" in capsys.readouterr().err
    assert main(["fit", str(corpus / "nope*.gml"), str(corpus), "-o", str(tmp_path / "o")]) == 2
    assert "nope*.gml: no file matches" in capsys.readouterr().err


def test_render_corpus_writes_one_picture_per_input(corpus, tmp_path, capsys):
    (corpus / "broken.gml").unlink()
    out = tmp_path / "pictures"
    assert (
        main(["render", str(corpus / "spec.gml"), str(corpus / "dust.json"), "-o", str(out)]) == 0
    )
    rows = summary(out / "summary.csv")
    assert sorted(p.name for p in out.glob("*.png")) == ["dust.png", "spec.png"]
    assert rows["dust.json"]["picture"].endswith("PNG")


def test_a_bug_in_one_file_becomes_its_row(tmp_path, monkeypatch):
    import tagbot.gesture

    def broken_fit(*args, **kwargs):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(tagbot.gesture, "reconstruction", broken_fit)
    [row] = list(map_files(fit_file, [FileJob(str(EXAMPLE), None, {})]))
    assert row["status"] == "error"
    assert "internal error ZeroDivisionError: boom" in row["error"]


@pytest.fixture(scope="module")
def dask_scheduler():
    """A local dask.distributed cluster (threads in this process) for the module's tests; its
    process-wide helper threads outlive it, so it is not made per test. Its web server takes any
    free loopback port (the default 8787 is taken when another suite runs beside this one)."""
    distributed = pytest.importorskip("distributed", reason="tagbot[dask] is not installed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address="127.0.0.1:0"
    ) as cluster:
        with distributed.Client(cluster.scheduler_address) as client:  # start the worker threads
            assert client.gather(client.map(abs, [-1, -2, -3, -4], pure=False)) == [1, 2, 3, 4]
        yield cluster.scheduler_address


def test_the_same_function_maps_over_a_dask_cluster(corpus, tmp_path, dask_scheduler):
    (corpus / "broken.gml").unlink()
    out = tmp_path / "plans"
    args = ["fit", str(corpus), "-o", str(out), "--no-report", "--scheduler", dask_scheduler]
    assert main(args) == 0
    local = tmp_path / "local"
    assert main(["fit", str(corpus), "-o", str(local), "--no-report", "--jobs", "1"]) == 0
    for plan in local.glob("*.json"):
        assert (out / plan.name).read_bytes() == plan.read_bytes()


def crash_on_marked_files(job: FileJob) -> dict:
    """``fit_file``, except that the worker process dies (as in a native crash) on crash*.gml."""
    import os

    if Path(job.source).name.startswith("crash"):
        os._exit(70)
    return fit_file(job)


def test_a_worker_that_dies_costs_only_its_own_file(corpus, tmp_path):
    (corpus / "broken.gml").unlink()
    shutil.copy(DATA / "spec10.gml", corpus / "crash.gml")
    jobs = [FileJob(p, None, {"report": False}) for p in expand_inputs([str(corpus)])]
    rows = {Path(r["input"]).name: r for r in map_files(crash_on_marked_files, jobs, workers=2)}
    assert sorted(rows) == ["crash.gml", "dust.json", "sideways.gml", "spec.gml"]
    assert rows["crash.gml"]["status"] == "error"
    assert "worker process died on this file" in rows["crash.gml"]["error"]
    assert all(rows[n]["status"] == "ok" for n in ("dust.json", "sideways.gml", "spec.gml"))
