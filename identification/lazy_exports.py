"""Names a package exports, each imported from its module when first asked for.

A package that re-exports its modules' public names (``from vehid.identification
import IOData``) would import every module, and with them SciPy, CasADi and HDF5,
on its own import. :func:`export_lazily` gives the package a module
``__getattr__`` (PEP 562) that imports a name's module on first use, and a
``__dir__`` that lists the names not yet imported.

Importing a submodule makes it an attribute of its package: a function
``linearize`` exported by the package would then be hidden by its module
``linearize``, whichever was imported first. The package's class is therefore
replaced by one that keeps the exported value under such a name (the submodule
stays importable through ``sys.modules``).
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any, Mapping, Sequence

__all__ = ["export_lazily"]


class _ExportingPackage(types.ModuleType):
    """A package whose exported names are never replaced by submodules of the same name."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and name in self.__dict__.get("_MODULE_OF", {}):
            return
        super().__setattr__(name, value)


def export_lazily(package_name: str, exports: Mapping[str, Sequence[str]]) -> dict[str, str]:
    """Make each name of ``exports`` (submodule -> names) an attribute of the package, imported on first use.

    Parameters
    ----------
    package_name : str
        The package's ``__name__``; called from its ``__init__``.
    exports : mapping of str to sequence of str
        Each submodule (relative, dotted) and the public names it defines.

    Returns
    -------
    dict
        Name -> submodule, also kept as the package's ``_MODULE_OF`` (the API
        reference reads it to group names by module).
    """
    package = sys.modules[package_name]
    module_of = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = module_of.get(name)
        if module is None:
            raise AttributeError(f"module {package_name!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package_name), name)
        vars(package)[name] = value  # later look-ups skip this function
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(package)) | set(module_of))

    package._MODULE_OF = module_of
    package.__getattr__ = __getattr__
    package.__dir__ = __dir__
    package.__class__ = _ExportingPackage
    return module_of
