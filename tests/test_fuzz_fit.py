"""Fuzzing end to end: mutated copies of the shipped example files, read, fitted and measured.

Every case ends in traces (then a plan and its report) or a one-line TagbotError naming the
file, within :data:`BUDGET` seconds; compiled kernels only ever see finite, bounded arguments
(the suite runs with :mod:`tagbot.kernel_check` on, so a bad argument fails the case).
"""

from __future__ import annotations

import json
import re
import time
from datetime import timedelta
from importlib import resources
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tagbot.errors import TagbotError
from tagbot.gesture import fit
from tagbot.inputs import read_traces_bytes
from tagbot.io.planfile import tag_from_dict
from tagbot.kernel_check import installed
from tagbot.metrics import fit_report

BUDGET = 20.0
"""Most seconds one case may take: read, fit, report (a few kB of input: usually < 1 s)."""

EXAMPLES = resources.files("tagbot") / "examples"
DATA = Path(__file__).parent / "inputs" / "data"
TRACE_FILES = [
    (EXAMPLES / "dusttag-142.json").read_bytes(),
    *(
        (DATA / name).read_bytes()
        for name in ("spec10.gml", "sideways.gml", "fattag.gml", "drawing.svg", "restart.gml")
    ),
]
PLAN_FILES = [(EXAMPLES / name).read_bytes() for name in ("cae.json", "letter-b.json")]
PROFILES = [
    ("tagbot.plotter.profile", (resources.files("tagbot") / "plotter" / "profiles" / name))
    for name in ("default.toml", "zpen.toml")
] + [("tagbot.arm.profile", resources.files("tagbot") / "arm" / "profiles" / "default.toml")]

ABSURD = [
    "1e308", "-1e308", "1e309", "nan", "inf", "-inf", "0", "-0", "1e-308", "5e-324", "1e15",
    "1e16", "123456789012345678901234567890", "-1", "0.5", "1262304000000", "2828", "1e12",
]  # fmt: skip

_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?")

FUZZ = settings(
    max_examples=60,
    deadline=timedelta(seconds=BUDGET),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def mutate(data: bytes, edits: list[tuple[str, int, int]]) -> bytes:
    """Replace numbers with absurd ones, duplicate or drop a span, or cut the file."""
    out = bytearray(data)
    for op, pos, pick in edits:
        numbers = list(_NUMBER.finditer(out))
        if op == "number" and numbers:
            m = numbers[pos % len(numbers)]
            out[m.start() : m.end()] = ABSURD[pick % len(ABSURD)].encode()
        elif op == "spread" and numbers:  # one number absurd everywhere it is a coordinate
            for m in reversed(numbers[pos % len(numbers) :: 1 + pick % 7]):
                out[m.start() : m.end()] = ABSURD[pick % len(ABSURD)].encode()
        elif op == "repeat" and out:
            i = pos % len(out)
            out[i:i] = out[i : i + 1 + pick * 4]
        elif op == "drop" and out:
            i = pos % len(out)
            del out[i : i + 1 + pick]
        elif op == "cut" and out:
            del out[pos % len(out) :]
    return bytes(out)


edits = st.lists(
    st.tuples(
        st.sampled_from(["number", "number", "spread", "repeat", "drop", "cut"]),
        st.integers(0, 1 << 20),
        st.integers(0, 255),
    ),
    min_size=1,
    max_size=6,
)


def _one_line_error(e: TagbotError, name: str) -> None:
    message = str(e)
    assert "\n" not in message, message
    assert message.startswith(f"{name}: ") or message.split(":")[0].startswith(
        ("traces", "plans", "dt")
    ), message


def test_the_suite_checks_kernel_arguments() -> None:
    assert installed()


@FUZZ
@given(seed=st.sampled_from(range(len(TRACE_FILES))), edits=edits)
def test_mutated_traces_fit_or_fail_clearly(seed: int, edits) -> None:
    data = mutate(TRACE_FILES[seed], edits)
    started = time.perf_counter()
    try:
        traces = read_traces_bytes(data, "fuzz.gml")
    except TagbotError as e:
        _one_line_error(e, "fuzz.gml")
        return
    try:
        tag = fit(traces)
    except TagbotError as e:
        _one_line_error(e, "fuzz.gml")
        return
    report = fit_report(traces, tag)
    assert np.isfinite(report.shape.mean) and report.strokes == tag.n_strokes
    assert time.perf_counter() - started < BUDGET


@FUZZ
@given(seed=st.sampled_from(range(len(PLAN_FILES))), edits=edits)
def test_mutated_plans_load_and_sample_or_fail_clearly(seed: int, edits) -> None:
    data = mutate(PLAN_FILES[seed], edits)
    try:
        document = json.loads(data.decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return  # not JSON: load_plan's own tests cover the message
    try:
        tag = tag_from_dict(document)
        motion = tag.sample(max(0.002, (tag.end - tag.start) / 20_000))
    except TagbotError as e:
        assert "\n" not in str(e)
        return
    assert np.isfinite(motion.xy).all() and np.isfinite(motion.v).all()


@FUZZ
@given(seed=st.sampled_from(range(len(PROFILES))), edits=edits)
def test_mutated_machine_profiles_load_or_fail_clearly(seed: int, edits, tmp_path_factory) -> None:
    import importlib

    module, source = PROFILES[seed]
    path = tmp_path_factory.mktemp("profile") / "machine.toml"
    path.write_bytes(mutate(source.read_bytes(), edits))
    try:
        importlib.import_module(module).load_profile(str(path))
    except TagbotError as e:
        assert "\n" not in str(e) and str(path) in str(e), str(e)


@FUZZ
@given(seed=st.sampled_from(range(len(PLAN_FILES))), edits=edits)
def test_mutated_motion_files_read_or_fail_clearly(seed: int, edits, tmp_path_factory) -> None:
    from tagbot.io.motionfile import read_motion_csv, write_motion_csv
    from tagbot.io.planfile import tag_from_dict

    folder = tmp_path_factory.mktemp("motion")
    clean = folder / "clean.csv"
    write_motion_csv(tag_from_dict(json.loads(PLAN_FILES[seed])).sample(0.05), clean)
    path = folder / "motion.csv"
    path.write_bytes(mutate(clean.read_bytes(), edits))
    try:
        table = read_motion_csv(path)
    except TagbotError as e:
        assert "\n" not in str(e) and str(e).startswith(f"{path}"), str(e)
        return
    assert np.isfinite(table.t).all() and np.isfinite(table.xy).all()
