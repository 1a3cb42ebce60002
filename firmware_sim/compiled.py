"""The one law, compiled: numba versions of the very functions agents run interpreted.

:func:`kernels` takes the plain-Python modules of the law and of the swarm step
(:data:`SOURCES`), gives each function a copy of its module's globals in which every other
function of those modules is replaced by its compiled version, and compiles them with
``numba.njit`` (``parallel`` for the loops written with ``prange``). Nothing is generated
by hand and nothing is written twice: the compiled and the interpreted runs execute the same
source, and ``tests/test_compiled.py`` checks that they give equal results.

The functions of :data:`INLINED` are inlined into their callers (numba's ``inline``, at its
own IR level): the safety governor's helpers run per neighbour, and the calls between
them, left to LLVM, stayed real calls (docs/performance.md).

Divisions follow numpy's error model: a division by zero gives inf or nan instead of
raising, which spares a test before every division (the law guards its own divisions, and
the compiled runs give the interpreted results, ``tests/test_compiled.py``).

numba caches the machine code, but it does not notice that a function it compiled calls a
function of another file that has changed since. So the cache lives in a folder named
after a hash of all the sources and of this module (``$BOUNDSWARM_NUMBA_CACHE``, else
``~/.cache/boundswarm/numba``): an edited law is compiled afresh, never taken stale.

numba is an optional dependency (the ``sim`` extra); agents never import this module.
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import logging
import os
import types
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

SOURCES = ("common.draws", "agent.kinematics", "agent.avoidance", "agent.braking",
           "agent.trail", "agent.discs", "agent.governor", "agent.law", "agent.formation",
           "agent.neighbours", "agent.exchange", "agent.period", "agent.odometry",
           "firmware_sim.world_step", "firmware_sim.swarm_step")
# modules whose functions are compiled into their callers (module docstring)
INLINED = ("agent.braking", "agent.trail", "agent.discs", "agent.governor")


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

    config: Any = numba.config      # its settings are set at run time (from the environment)
    numba.set_num_threads(config.NUMBA_NUM_THREADS if parallel else 1)


def cache_dir(modules: list[types.ModuleType], numba_version: str) -> Path:
    """The folder of the machine code compiled from ``modules``' current sources, as
    this module compiles them."""
    digest = hashlib.sha256(numba_version.encode())
    digest.update(Path(__file__).read_bytes())      # how they are compiled
    for m in modules:
        digest.update(Path(m.__file__ or "").read_bytes())
    root = os.environ.get("BOUNDSWARM_NUMBA_CACHE")
    base = Path(root) if root else Path.home() / ".cache" / "boundswarm" / "numba"
    return base / digest.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def kernels() -> types.SimpleNamespace:
    """The compiled functions of :data:`SOURCES`, by name (compiled at their first call, or
    loaded from the cache of these very sources)."""
    import numba

    modules = [importlib.import_module(name) for name in SOURCES]
    config: Any = numba.config      # its settings are set at run time (from the environment)
    previous = config.CACHE_DIR
    config.CACHE_DIR = str(cache_dir(modules, numba.__version__))
    try:
        return _compile(modules, numba)
    finally:
        config.CACHE_DIR = previous


def _compile(modules: list[types.ModuleType], numba: Any) -> types.SimpleNamespace:
    """numba.njit each function of ``modules`` in globals that name the compiled ones."""
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
                                            parallel="prange" in code.co_names,
                                            error_model="numpy",
                                            inline="always" if m.__name__ in INLINED
                                            else "never")
    for ns in namespaces.values():
        for name, obj in list(ns.items()):
            if isinstance(obj, types.FunctionType) and obj in originals:
                ns[name] = originals[obj]
    return types.SimpleNamespace(**{f.__name__: jit for f, jit in originals.items()})
