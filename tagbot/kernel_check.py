"""A debug mode proving that compiled kernels only ever see validated input.

numba kernels run without Python's checks: fed NaN, infinities or absurd magnitudes they can
loop for ever or read out of bounds. Every kernel is reached from Python through a module
attribute (``kernels.evaluate(...)``, ``refine_kernels.refine_loop(...)``); with the environment
variable ``TAGBOT_CHECK_KERNELS=1`` set before ``import tagbot`` (or after :func:`install`),
those attributes are replaced by proxies that check every argument before the call:

* floating and complex arrays and numbers are finite (no NaN, no ±inf);
* only parameters named in :data:`BOUNDS` (box constraints) may be ±inf, never NaN.

Magnitudes are bounded where input enters (the readers' and plans' documented limits); the
kernels themselves are tested at extreme magnitudes, so this mode checks finiteness only.

A violation raises :class:`KernelInputError` naming the kernel and the argument: a bug in the
validation in front of it, never a user's error. Kernels calling kernels inside compiled code
are untouched (the proxies sit only where Python calls in). The test suite runs in this mode.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import os
import sys
from types import ModuleType
from typing import Any

import numpy as np

__all__ = ["BOUNDS", "ENV", "KernelInputError", "check_arguments", "install", "installed"]

ENV = "TAGBOT_CHECK_KERNELS"


BOUNDS = frozenset({"lower", "upper"})
"""Kernel parameters that are bounds, where ±inf means unbounded."""


class KernelInputError(AssertionError):
    """A compiled kernel was about to be called with a non-finite argument."""


def check_arguments(
    name: str, args: tuple[Any, ...], kwargs: dict[str, Any], names: tuple[str, ...] = ()
) -> None:
    """Raise :class:`KernelInputError` unless every argument is finite (``names`` are the
    parameters' names, for the message and :data:`BOUNDS`)."""
    for where, value in [*enumerate(args), *kwargs.items()]:
        label = names[where] if isinstance(where, int) and where < len(names) else where
        if label in BOUNDS and isinstance(value, np.ndarray) and value.dtype.kind == "f":
            value = np.where(np.isinf(value), 0.0, value)
        problem = _problem(value)
        if problem:
            raise KernelInputError(f"kernel {name}: argument {label!s} {problem}")


def _problem(value: Any) -> str | None:
    if isinstance(value, bool | str | None):
        return None
    if isinstance(value, int | float | complex | np.number):
        value = np.asarray(value)
    if isinstance(value, tuple | list):
        for i, item in enumerate(value):
            problem = _problem(item)
            if problem:
                return f"[{i}] {problem}"
        return None
    if not isinstance(value, np.ndarray) or value.size == 0:
        return None
    if value.dtype.kind in "fc" and not np.isfinite(value).all():
        bad = int(np.flatnonzero(~np.isfinite(value.ravel()))[0])
        return f"is not finite (element {bad}: {value.ravel()[bad]!r})"
    return None


class _Checked:
    """A kernels module whose compiled functions check their arguments first."""

    def __init__(self, module: ModuleType) -> None:
        self._module = module
        self.__name__ = module.__name__
        self.__doc__ = module.__doc__

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._module, name)
        if not hasattr(value, "py_func"):  # not a numba dispatcher: constants, helpers
            return value

        names = tuple(inspect.signature(value.py_func).parameters)

        @functools.wraps(value.py_func)
        def checked(*args: Any, **kwargs: Any) -> Any:
            check_arguments(f"{self.__name__}.{name}", args, kwargs, names)
            return value(*args, **kwargs)

        setattr(self, name, checked)  # built once per kernel
        return checked


def install() -> int:
    """Put checking proxies in front of every kernels module that a loaded tagbot module calls
    through; returns how many references were replaced. Idempotent."""
    for package in ("tagbot.gesture", "tagbot.model", "tagbot.metrics"):  # kernels callers
        importlib.import_module(package)

    replaced = 0
    for module in list(sys.modules.values()):
        name = getattr(module, "__name__", "")
        if not name.startswith("tagbot.") or name.endswith("kernels"):
            continue
        for attr, value in list(vars(module).items()):
            if (
                isinstance(value, ModuleType)
                and value.__name__.startswith("tagbot.")
                and value.__name__.endswith("kernels")
            ):
                setattr(module, attr, _Checked(value))
                replaced += 1
    return replaced


def installed() -> bool:
    """Whether the proxies are in front of the kernels (for tests)."""
    import tagbot.gesture.reconstruct as reconstruct

    return isinstance(reconstruct.kernels, _Checked)


if os.environ.get(ENV, "") not in ("", "0"):  # pragma: no cover - exercised by the test suite
    install()
