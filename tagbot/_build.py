"""tagbot's build backend: setuptools', plus the compiled kernels in the wheel.

``build_wheel`` builds the wheel with setuptools, runs :func:`tagbot.warmup.warm_up` on the
wheel's own files in a fresh interpreter, and adds the numba cache files it wrote
(``__pycache__/*.nbi``, ``*.nbc``) to the wheel and its RECORD. ``pip install .`` therefore
compiles the kernels once, for the machine that installs, and the first ``tagbot demo`` loads
them instead of compiling for a minute. numba checks every cached kernel against its source's
contents, the interpreter, numba's version and the CPU, and compiles again on any mismatch, so a
wheel carried to another machine still works. ``TAGBOT_WARM_UP=0`` builds a wheel without the
cache (for a wheel meant for other machines); a failed warm-up only warns.
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from types import ModuleType
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

WARM_UP_NEEDS = ("numpy", "scipy", "numba", "defusedxml")
"""The runtime dependencies the warm-up imports (their versions as ``pyproject.toml`` asks)."""
WARM_UP_TIMEOUT = 1800.0
"""Seconds the warm-up may take before the wheel is built without it."""


SETUPTOOLS_HOOKS = (
    "build_editable",
    "build_sdist",
    "get_requires_for_build_editable",
    "get_requires_for_build_sdist",
    "prepare_metadata_for_build_editable",
    "prepare_metadata_for_build_wheel",
)
"""The backend's other hooks: setuptools' own."""


def _setuptools() -> ModuleType:
    from setuptools import build_meta

    return build_meta


def __getattr__(name: str) -> Any:
    if name in SETUPTOOLS_HOOKS:
        return getattr(_setuptools(), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _enabled() -> bool:
    return os.environ.get("TAGBOT_WARM_UP", "1").strip().lower() not in ("0", "no", "false")


def _warm_up_requirements() -> list[str]:
    """``pyproject.toml``'s requirements for the packages in :data:`WARM_UP_NEEDS`."""
    project = tomllib.loads(Path("pyproject.toml").read_text(encoding="utf-8"))["project"]
    wanted = []
    for requirement in project["dependencies"]:
        name = re.match(r"[A-Za-z0-9._-]+", requirement)
        if name and name.group(0).lower() in WARM_UP_NEEDS:
            wanted.append(requirement)
    return wanted


def get_requires_for_build_wheel(config_settings: dict | None = None) -> list[str]:
    needs = _setuptools().get_requires_for_build_wheel(config_settings)
    return [*needs, *_warm_up_requirements()] if _enabled() else needs


def build_wheel(
    wheel_directory: str, config_settings: dict | None = None, metadata_directory: str | None = None
) -> str:
    name = _setuptools().build_wheel(wheel_directory, config_settings, metadata_directory)
    if _enabled():
        _add_kernel_cache(Path(wheel_directory) / name)
    return name


def _add_kernel_cache(wheel: Path, module: str = "tagbot.warmup") -> None:
    """Run ``python -m module`` on the wheel's files and add the numba cache files it wrote."""
    with tempfile.TemporaryDirectory(prefix="tagbot-warm-up-") as tmp:
        tree = Path(tmp) / "wheel"
        with zipfile.ZipFile(wheel) as archive:
            archive.extractall(tree)
        env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "TAGBOT_"))}
        # The build environment's own path entries stay (pip's isolation lives in PYTHONPATH).
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
        print("tagbot: compiling the kernels for this machine (a minute or two)", file=sys.stderr)
        try:
            done = subprocess.run(
                [sys.executable, "-m", module],
                cwd=tmp,
                env=env,
                capture_output=True,
                text=True,
                timeout=WARM_UP_TIMEOUT,
            )
        except (OSError, subprocess.TimeoutExpired) as error:
            print(f"tagbot: warm-up skipped ({error}); kernels compile on use", file=sys.stderr)
            return
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            print(f"tagbot: warm-up failed ({last}); kernels compile on use", file=sys.stderr)
            return
        print(f"tagbot: {done.stdout.strip()}", file=sys.stderr)
        cache = sorted(p for p in tree.rglob("__pycache__/*") if p.suffix in (".nbi", ".nbc"))
        _append(wheel, {p.relative_to(tree).as_posix(): p.read_bytes() for p in cache})


def _append(wheel: Path, files: dict[str, bytes]) -> None:
    """Rewrite ``wheel`` with ``files`` (archive name → content) added and listed in RECORD."""
    partial = wheel.with_name(wheel.name + ".partial")
    with zipfile.ZipFile(wheel) as old, zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as new:
        record = next(i for i in old.infolist() if i.filename.endswith(".dist-info/RECORD"))
        lines = [line for line in old.read(record).decode().splitlines() if line]
        for info in old.infolist():
            if info is not record:
                new.writestr(info, old.read(info))
        for name, data in files.items():
            info = zipfile.ZipInfo(name, date_time=record.date_time)
            info.external_attr = 0o644 << 16
            new.writestr(info, data, zipfile.ZIP_DEFLATED)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
            lines.insert(len(lines) - 1, f"{name},sha256={digest.decode()},{len(data)}")
        new.writestr(record, "\n".join(lines) + "\n")
    partial.replace(wheel)
