"""Lazy package exports (PEP 562): a name's module is imported on first use, so importing a
package (and starting the CLI) does not load numpy, scipy or numba until they are needed."""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable, Mapping
from typing import Any


class _Package(types.ModuleType):
    """A package whose exported names win over its submodules of the same name (``place`` the
    function, not ``place`` the module), as when the package imported them eagerly."""

    _exports: Mapping[str, str] = types.MappingProxyType({})

    def __setattr__(self, name: str, value: Any) -> None:
        if (
            isinstance(value, types.ModuleType)
            and name in self._exports
            and value.__name__ == f"{self.__name__}.{name}"
        ):
            return  # the import system binding a submodule: the export stays what the name means
        super().__setattr__(name, value)


def lazy_exports(
    package: str, exports: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` whose ``exports`` map each public name to
    the module (absolute, or relative to ``package`` with a leading dot) that defines it."""
    module = sys.modules[package]
    namespace = module.__dict__
    module.__class__ = _Package
    namespace["_exports"] = dict(exports)

    def __getattr__(name: str) -> Any:
        source = exports.get(name)
        if source is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(source, package), name)
        namespace[name] = value  # later lookups skip this function
        return value

    def __dir__() -> list[str]:
        return sorted({*namespace, *exports})

    return __getattr__, __dir__
