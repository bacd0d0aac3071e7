"""Seeded, function-stratified mutation sample (issue 34), with per-module scores.

mutmut 3 has no sampling of its own. This script generates the mutants of the modules listed
under ``[tool.mutmut] only_mutate`` in pyproject.toml (as ``mutmut run`` does), draws a seeded
sample per module, stratified by function (functions in a seeded random order, one mutant of
each in turn, until the module's quota is met), runs it with ``mutmut run --max-children N
<names>`` and prints, per module, the killed share of the non-equivalent mutants. Equivalent
mutants are those listed in tests/EQUIVALENT_MUTANTS.txt (one per line: name, then the reason).

    python tools/mutation_sample.py                       # 40 per module, seed 0
    python tools/mutation_sample.py --per-module 20 --seed 7 --module tagbot/plotter/program.py
    python tools/mutation_sample.py --list                # the sample only, nothing run

Run from the repository root (mutmut writes its copy under ./mutants); needs mutmut 3.8.
A timeout counts as killed (the tests noticed); "no tests" counts as survived.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

EQUIVALENTS = Path("tests/EQUIVALENT_MUTANTS.txt")
KILLED = {"killed", "timeout", "caught by type check", "segfault"}


def configuration() -> dict:
    """pyproject.toml's ``[tool.mutmut]`` table."""
    import tomllib

    with open("pyproject.toml", "rb") as f:
        return tomllib.load(f)["tool"]["mutmut"]


def generate() -> None:
    """Write ./mutants with every mutant of the configured modules (mutmut's own first step)."""
    from mutmut.__main__ import create_mutants
    from mutmut.utils.file_utils import copy_also_copy_files, copy_src_dir, setup_source_paths

    os.makedirs("mutants", exist_ok=True)
    copy_src_dir()
    copy_also_copy_files()
    setup_source_paths()
    create_mutants(1)


def exit_codes(module: str) -> dict[str, int | None]:
    """Mutant name to mutmut's exit code (None: not run yet) for one module file."""
    with open(Path("mutants") / f"{module}.meta") as f:
        return json.load(f)["exit_code_by_key"]


def function_of(name: str) -> str:
    """The function a mutant belongs to: ``pkg.mod.x_f__mutmut_3`` → ``pkg.mod.x_f``."""
    return name.rsplit("__mutmut_", 1)[0]


def stratified(names: list[str], count: int, rng: random.Random) -> list[str]:
    """``count`` names drawn round-robin over functions taken in a random order."""
    by_function: dict[str, list[str]] = defaultdict(list)
    for name in sorted(names):
        by_function[function_of(name)].append(name)
    pools = [by_function[f] for f in sorted(by_function)]
    rng.shuffle(pools)
    for pool in pools:
        rng.shuffle(pool)
    picked: list[str] = []
    while len(picked) < min(count, len(names)):
        for pool in pools:
            if pool and len(picked) < count:
                picked.append(pool.pop())
    return picked


def equivalents() -> dict[str, str]:
    """Listed equivalent mutants: name to reason."""
    if not EQUIVALENTS.exists():
        return {}
    listed = {}
    for line in EQUIVALENTS.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            name, _, reason = line.strip().partition(" ")
            listed[name] = reason.strip()
    return listed


def main(argv: list[str] | None = None) -> int:
    """Parse the options, sample, run and print the scores; 0 when every module reaches --goal."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--module", action="append", help="a file of only_mutate (repeatable)")
    parser.add_argument("--per-module", type=int, default=40, help="sample size per module")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-children", type=int, default=1)
    parser.add_argument("--goal", type=float, default=90.0, help="percent killed per module")
    parser.add_argument("--list", action="store_true", help="print the sample, run nothing")
    args = parser.parse_args(argv)

    config = configuration()
    modules = list(config["only_mutate"])
    unknown = sorted(set(args.module or []) - set(modules))
    if unknown:
        print(f"pyproject.toml: {', '.join(unknown)} not in [tool.mutmut] only_mutate")
        return 2
    modules = args.module or modules
    generate()
    sample = {  # each module's own seeded draw: the same whichever modules are run with it
        m: stratified(
            list(exit_codes(m)),
            args.per_module,
            random.Random(f"{args.seed}:{m}"),
        )
        for m in modules
    }
    if args.list:
        for names in sample.values():
            print("\n".join(names))
        return 0
    names = [n for picked in sample.values() for n in picked]
    # this interpreter's mutmut: the one installed beside tagbot, whether or not its venv is active
    command = [sys.executable, "-m", "mutmut", "run", "--max-children", str(args.max_children)]
    command += names
    subprocess.run(command, check=False)

    from mutmut.stats import status_by_exit_code

    listed = equivalents()
    worst = 100.0
    print(f"\nseed {args.seed}, {args.per_module} per module")
    for module, picked in sample.items():
        codes = exit_codes(module)
        status = {n: status_by_exit_code[codes[n]] for n in picked}
        equivalent = [n for n in picked if n in listed]
        counted = [n for n in picked if n not in listed]
        killed = [n for n in counted if status[n] in KILLED]
        score = 100.0 * len(killed) / len(counted) if counted else 100.0
        worst = min(worst, score)
        print(
            f"{module}: {len(killed)}/{len(counted)} killed ({score:.0f} %), "
            f"{len(equivalent)} equivalent"
        )
        for name in counted:
            if status[name] not in KILLED:
                print(f"    {status[name]}: {name}")
    return 0 if worst >= args.goal else 1


if __name__ == "__main__":
    sys.exit(main())
