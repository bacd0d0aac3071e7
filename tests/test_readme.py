"""The README's Python examples run as written (from a folder holding the shipped examples)."""

import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


def test_readme_has_python_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_example_runs(index, tmp_path, monkeypatch, capsys):
    shutil.copytree(ROOT / "tagbot" / "examples", tmp_path / "tagbot" / "examples")
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[index], f"README.md python block {index}", "exec"), {})


def _commands(group, prefix=""):
    """Every leaf command of the click group, by its full name."""
    import click

    for name, command in group.commands.items():
        full = f"{prefix}{name}"
        if isinstance(command, click.Group):
            yield from _commands(command, f"{full} ")
        else:
            yield full, command


def test_the_command_line_synopsis_lists_every_option():
    """Each command's synopsis line under "Command line" names every option it takes."""
    from tagbot.cli import cli

    section = (ROOT / "README.md").read_text().split("## Command line", 1)[1]
    synopsis = re.search(r"```text\n(.*?)```", section, flags=re.S).group(1)
    lines = {}
    for line in synopsis.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0] == "tagbot":
            lines.setdefault(words[1], []).append(line)
    missing = []
    for name, command in _commands(cli):
        first = name.split()[0]
        text = " ".join(lines.get(first, []))
        assert text, f"no synopsis line for tagbot {name}"
        for param in command.params:
            names = [o for o in (*param.opts, *param.secondary_opts) if o.startswith("-")]
            if names and "--help" not in names and not any(o in text for o in names):
                missing.append(f"tagbot {name} {names[0]}")
    assert not missing, missing
