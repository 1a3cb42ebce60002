"""The one law, compiled: numba versions of the very functions agents run interpreted.

:func:`kernels` takes the plain-Python modules of the law and of the swarm step
(:data:`SOURCES`), gives each function a copy of its module's globals in which every other
function of those modules is replaced by its compiled version, and compiles them with
``numba.njit`` (``parallel`` for the loops written with ``prange``). Nothing is generated
by hand and nothing is written twice: the compiled and the interpreted runs execute the same
source, and ``tests/test_compiled.py`` checks that they give equal results.

numba is an optional dependency (the ``sim`` extra); agents never import this module.
"""
from __future__ import annotations

import functools
import importlib
import logging
import types
from typing import Any

log = logging.getLogger(__name__)

SOURCES = ("agent.kinematics", "agent.avoidance", "agent.law", "agent.formation",
           "firmware_sim.swarm_step")


def available() -> bool:
    """Whether numba can be imported."""
    try:
        importlib.import_module("numba")
    except ImportError:
        return False
    return True


def use_threads(parallel: bool) -> None:
    """Run the ``prange`` loops on all of numba's threads, or on the calling one only."""
    import numba

    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS if parallel else 1)


@functools.lru_cache(maxsize=1)
def kernels() -> types.SimpleNamespace:
    """The compiled functions of :data:`SOURCES`, by name (compiled at their first call;
    numba caches the machine code next to the sources)."""
    import numba

    modules = [importlib.import_module(name) for name in SOURCES]
    namespaces = {m.__name__: dict(vars(m)) for m in modules}
    for ns in namespaces.values():
        if "prange" in ns:
            ns["prange"] = numba.prange
    originals: dict[Any, Any] = {}
    for m in modules:
        for name, obj in vars(m).items():
            if isinstance(obj, types.FunctionType) and obj.__module__ == m.__name__:
                code = obj.__code__
                copy = types.FunctionType(code, namespaces[m.__name__], name,
                                          obj.__defaults__, obj.__closure__)
                originals[obj] = numba.njit(copy, cache=True,
                                            parallel="prange" in code.co_names)
    for ns in namespaces.values():
        for name, obj in list(ns.items()):
            if isinstance(obj, types.FunctionType) and obj in originals:
                ns[name] = originals[obj]
    return types.SimpleNamespace(**{f.__name__: jit for f, jit in originals.items()})
