"""Names of a package loaded on first use (PEP 562): ``import planner`` or writing a plan's
output must not load numba, scipy or shapely before a name that needs them is used."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["lazy_getattr"]


def lazy_getattr(package: str, home: dict[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: a name of ``home`` (name -> submodule) is
    imported from its submodule on first use and kept in the package's namespace."""

    def __getattr__(name: str) -> Any:
        where = home.get(name)
        if where is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{where}", package), name)
        setattr(importlib.import_module(package), name, value)
        return value

    return __getattr__
