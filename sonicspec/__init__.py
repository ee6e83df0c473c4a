"""sonicspec: realistic moving-source speech datasets from a versioned spec.

The Python API (:mod:`sonicspec.api`) is importable from here: ``sonicspec.Scene``,
``sonicspec.compute_rir``, ``sonicspec.compute_rirs``, ``sonicspec.RirSettings`` and
``sonicspec.RirResult``. It is loaded on first use, so the command line stays quick.

Compiled kernels (numba) are cached in ``$SONICSPEC_NUMBA_CACHE_DIR``, else numba's own
``$NUMBA_CACHE_DIR``, else ``$XDG_CACHE_HOME/sonicspec/numba`` (``~/.cache/sonicspec/numba``):
never in the installed source tree, which every cluster node would write at once.
"""

import os as _os
import sys as _sys

__version__ = "0.1.0.dev0"

NUMBA_CACHE_ENV = "SONICSPEC_NUMBA_CACHE_DIR"


def numba_cache_dir() -> str:
    """Where numba caches sonicspec's compiled kernels (see the module docstring)."""
    chosen = _os.environ.get(NUMBA_CACHE_ENV) or _os.environ.get("NUMBA_CACHE_DIR")
    if chosen:
        return _os.path.abspath(_os.path.expanduser(chosen))
    base = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"),
                                                              ".cache")
    return _os.path.join(base, "sonicspec", "numba")


def _use_numba_cache_dir() -> None:
    # numba reads NUMBA_CACHE_DIR when it is imported, and a kernel module reads numba's
    # config when it is imported: set both before any kernel module is. Job processes inherit
    # the variable.
    where = numba_cache_dir()
    _os.environ["NUMBA_CACHE_DIR"] = where
    config = _sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = where


_use_numba_cache_dir()

__all__ = ["RirResult", "RirSettings", "Scene", "__version__", "compute_rir", "compute_rirs"]

_API = ("RirResult", "RirSettings", "Scene", "compute_rir", "compute_rirs")


def __getattr__(name: str):
    if name in _API:
        from sonicspec import api

        return getattr(api, name)
    raise AttributeError(f"module 'sonicspec' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])
