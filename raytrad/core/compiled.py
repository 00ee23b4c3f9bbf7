"""Compiled form-factor kernels: the numba adapter.

The form-factor pass evaluates Lambert's formula for millions of small (receiver,
polygon) pairs: a patch's outline (whole or clipped to a receiver's horizon), near
triangles of a sub-area, the parts of a triangle split for
:func:`~raytrad.core.kernels.linear_corner_shares`. In numpy each of those is a chain of
small temporaries; here each pair is one loop, compiled once (``cache=True``, so later
processes load it from disk) and run without the GIL (``nogil=True``), so the
form-factor engine's threads run on every core.

:mod:`raytrad.core.kernels`, :mod:`raytrad.core.contour`, :mod:`raytrad.core.gather`,
:mod:`raytrad.core.spread`, :mod:`raytrad.core.clusters` and :mod:`raytrad.core.pairs`
keep the numpy implementations as the reference: every function here computes the same
formula in the same order, and the tests compare the two to 1e-12 on random and
adversarial pairs (grazing, coplanar, straddling the horizon).
numba is imported only when a kernel is first asked for (:func:`get`), and
``RAYTRAD_KERNELS=numpy`` in the environment keeps the numpy path.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from types import SimpleNamespace
from typing import Any

log = logging.getLogger(__name__)

_LOCK = threading.Lock()
_STATE: dict[str, Any] = {}


def wanted() -> bool:
    """Whether compiled kernels are asked for: ``RAYTRAD_KERNELS`` is not ``numpy``."""
    return os.environ.get("RAYTRAD_KERNELS", "compiled").strip().lower() != "numpy"


def get() -> SimpleNamespace | None:
    """The compiled kernels, or None (numba missing, or ``RAYTRAD_KERNELS=numpy``).

    Compiles (or loads from numba's cache) on the first call; thread-safe.
    """
    if not wanted():
        return None
    if "kernels" in _STATE:
        return _STATE["kernels"]
    with _LOCK:
        if "kernels" not in _STATE:
            _STATE["kernels"] = _build()
    return _STATE["kernels"]


def _build() -> SimpleNamespace | None:
    start = time.perf_counter()
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        log.warning("numba is not installed: form factors use the slower numpy kernels")
        return None
    from raytrad.core import (
        _compiled_gather,
        _compiled_kernels,
        _compiled_near,
        _compiled_shafts,
        _compiled_solver,
    )

    kernels = {}
    modules = (
        _compiled_kernels,
        _compiled_near,
        _compiled_gather,
        _compiled_shafts,
        _compiled_solver,
    )
    for loops in modules:
        for name in loops.KERNELS:
            if not hasattr(getattr(loops, name), "py_func"):  # not compiled yet
                setattr(loops, name, _jit(numba, getattr(loops, name)))
            kernels[name] = getattr(loops, name)
    log.debug("compiled kernels ready in %.2f s", time.perf_counter() - start)
    return SimpleNamespace(**kernels)


def _jit(numba: Any, function: Any) -> Any:
    """``numba.njit(cache=True, nogil=True)``, without the disk cache where numba finds no
    writable place for it (a read-only install and no home directory): compiled anew in
    each process then, never an error."""
    try:
        return numba.njit(cache=True, nogil=True)(function)
    except RuntimeError as error:  # numba: "cannot cache function ...: no locator"
        log.debug("numba cannot cache %s (%s): compiling without a cache", function, error)
        return numba.njit(nogil=True)(function)
