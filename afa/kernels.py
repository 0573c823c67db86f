"""Loading afa's compiled kernels (decision 0014): one rule for every numba kernel.

A kernel lives in its own ``_…_jit`` module beside the numpy or pure-Python form it
compiles; importing that module compiles the kernel, or loads it from numba's on-disk
cache. :func:`compiled` imports it and answers None, so the caller runs its own form,
when ``AFA_KERNELS=numpy`` asks for the plain forms, when numba is not installed
(quietly), or when the kernel cannot be compiled or cached here (with a warning).
"""

from __future__ import annotations

import importlib
import logging
import os
from typing import Any

__all__ = ["compiled", "plain_forms_requested"]


def plain_forms_requested() -> bool:
    """Whether ``AFA_KERNELS=numpy`` asks for the plain (numpy or Python) forms."""
    return os.environ.get("AFA_KERNELS", "").lower() == "numpy"


def compiled(module: str, name: str) -> Any | None:
    """The kernel ``name`` of ``module``, or None for the caller's plain form."""
    if plain_forms_requested():
        return None
    try:
        return getattr(importlib.import_module(module), name)
    except Exception as exc:  # no numba, or it cannot compile or cache here
        if not (isinstance(exc, ModuleNotFoundError) and exc.name == "numba"):
            logging.getLogger(module).warning("compiled kernel %s unavailable (%s): "
                                              "plain fallback", name, exc)
        return None
