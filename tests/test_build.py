"""The build backend (``tagbot._build``): compiled kernels in the wheel, valid once installed."""

from __future__ import annotations

import base64
import csv
import hashlib
import io
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tagbot import _build

ROOT = Path(__file__).resolve().parents[1]

KERNEL = """\
from numba import njit


@njit(cache=True)
def twice(x):
    return 2.0 * x
"""


def _wheel(path: Path) -> Path:
    """A minimal wheel of a package ``kernpkg`` whose module ``kernpkg`` runs its kernel."""
    files = {
        "kernpkg/__init__.py": "",
        "kernpkg/kern.py": KERNEL,
        "kernpkg/__main__.py": "from kernpkg.kern import twice\nprint(twice(2.0))\n",
        "kernpkg-1.0.dist-info/METADATA": "Metadata-Version: 2.1\nName: kernpkg\nVersion: 1.0\n",
    }
    record = [f"{name},," for name in files] + ["kernpkg-1.0.dist-info/RECORD,,"]
    wheel = path / "kernpkg-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        for name, text in files.items():
            archive.writestr(name, text)
        archive.writestr("kernpkg-1.0.dist-info/RECORD", "\n".join(record) + "\n")
    return wheel


def _run_kernel(where: Path) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(where), NUMBA_DEBUG_CACHE="1")
    done = subprocess.run(
        [sys.executable, "-m", "kernpkg"], env=env, capture_output=True, text=True, check=True
    )
    return done.stdout


def test_the_wheel_gets_the_cache_with_its_record_and_the_cache_loads_once_installed(tmp_path):
    wheel = _wheel(tmp_path)
    _build._add_kernel_cache(wheel, module="kernpkg")
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        cached = [n for n in names if n.startswith("kernpkg/__pycache__/kern.twice-")]
        assert {Path(n).suffix for n in cached} == {".nbi", ".nbc"}
        rows = list(csv.reader(io.StringIO(archive.read("kernpkg-1.0.dist-info/RECORD").decode())))
        listed = {row[0]: row for row in rows}
        assert set(listed) == set(names)  # every file listed once, RECORD itself included
        for name in cached:
            data = archive.read(name)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
            assert listed[name][1:] == [f"sha256={digest.decode()}", str(len(data))]
        # Installed elsewhere, with new modification times (pip does not keep them).
        installed = tmp_path / "site-packages"
        archive.extractall(installed)
    out = _run_kernel(installed)
    assert "4.0" in out and "data loaded from" in out and "data saved to" not in out


def test_a_failing_warm_up_leaves_the_wheel_as_it_was(tmp_path, capsys):
    wheel = _wheel(tmp_path)
    before = wheel.read_bytes()
    _build._add_kernel_cache(wheel, module="no_such_module_here")
    assert wheel.read_bytes() == before
    assert "warm-up failed" in capsys.readouterr().err


def test_the_warm_up_needs_what_the_project_asks_for(monkeypatch):
    monkeypatch.chdir(ROOT)
    needs = _build._warm_up_requirements()
    assert sorted(n.split(">")[0].split("=")[0] for n in needs) == sorted(_build.WARM_UP_NEEDS)


@pytest.mark.parametrize("value", ["0", "no", "False"])
def test_warm_up_can_be_turned_off(monkeypatch, value):
    monkeypatch.setenv("TAGBOT_WARM_UP", value)
    assert not _build._enabled()


SIGNATURES = """\
import json, sys
from numba.core.registry import CPUDispatcher


def signatures():
    found = set()
    for name, module in list(sys.modules.items()):
        if name.startswith("tagbot"):
            for attr, value in list(vars(module).items()):
                if isinstance(value, CPUDispatcher):
                    found.update(f"{name}.{attr}{sig}" for sig in value.signatures)
    return found


from tagbot.warmup import warm_up

warm_up()
before = signatures()
from tagbot.cli import main

code = main(["demo", "--out", sys.argv[1]])
print(json.dumps({"code": code, "new": sorted(signatures() - before), "warm": len(before)}))
"""


def test_the_warm_up_compiles_every_kernel_the_demo_needs(tmp_path):
    # A fresh interpreter holds only what the warm-up compiled (or loaded from the cache); the
    # demo after it must not need one more kernel or one more signature of a kernel.
    done = subprocess.run(
        [sys.executable, "-c", SIGNATURES, str(tmp_path / "demo")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] == 0 and result["warm"] > 20
    assert result["new"] == [], f"the warm-up misses {result['new']}"
