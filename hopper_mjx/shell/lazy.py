"""A package's public names loaded on first use, so that importing the package (and a command's argument checks)
does not import JAX, MuJoCo or Brax."""

from __future__ import annotations

import importlib


def attributes(package: str, names: dict[str, str], namespace: dict):
    """A module-level `__getattr__` for `package`: each of `names` ({name: module}) imported from its module on
    first use and kept in `namespace` (the package's globals), so that later lookups skip this function."""

    def __getattr__(name: str):
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = namespace[name] = getattr(importlib.import_module(names[name]), name)
        return value

    return __getattr__
