"""Public names of a package imported from their modules on first use (PEP 562).

The heavy packages (``nav`` pulls in the compiled kernels and scipy, ``gnss`` the decoders)
re-export their public API this way, so that importing one light module of them (the Earth
model, the GNSS time scales) does not pay for the rest.
"""
from __future__ import annotations

import importlib
import sys


def lazy_exports(package: str, module_of: dict[str, str]):
    """``(__getattr__, __dir__, __all__)`` for a package whose public name N lives in its
    module ``module_of[N]``; a name is imported once, then it is an attribute of the package."""
    names = sorted(module_of)

    def __getattr__(name: str):
        module = module_of.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__, names
