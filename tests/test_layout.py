"""Import direction between the top-level packages.

``firmware_protocols`` is shared by the host and the simulators, so it imports neither; ``sim``
stands in for hardware, so it sees tagbot only through the wire protocols and never imports it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "firmware_protocols": {"tagbot", "sim"},
    "sim": {"tagbot"},
}


def imported_top_level_names(path: Path) -> set[str]:
    """Top-level package names a module imports (absolute imports and literal dynamic ones)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
        elif isinstance(node, ast.Call) and node.args:
            func, first = node.func, node.args[0]
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if (
                name in ("import_module", "__import__")
                and isinstance(first, ast.Constant)
                and isinstance(first.value, str)
            ):
                names.add(first.value.split(".")[0])
    return names


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_does_not_import_upwards(package: str) -> None:
    found = modules(package)
    assert found, f"no modules found under {package}/"
    offenders = {
        str(path.relative_to(ROOT)): sorted(imported_top_level_names(path) & FORBIDDEN[package])
        for path in found
    }
    offenders = {path: names for path, names in offenders.items() if names}
    assert not offenders, f"{package} must not import {sorted(FORBIDDEN[package])}: {offenders}"


def test_checker_sees_every_import_form(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text(
        "import os, tagbot.model\n"
        "from sim.grbl import X\n"
        "from . import sibling\n"
        "import importlib\n"
        "def f():\n"
        "    importlib.import_module('tagbot.cli')\n"
        "    __import__('serial')\n",
        encoding="utf-8",
    )
    assert imported_top_level_names(module) == {"os", "tagbot", "sim", "importlib", "serial"}
