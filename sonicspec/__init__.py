"""sonicspec: realistic moving-source speech datasets from a versioned spec.

The Python API (:mod:`sonicspec.api`) is importable from here: ``sonicspec.Scene``,
``sonicspec.compute_rir``, ``sonicspec.compute_rirs``, ``sonicspec.RirSettings`` and
``sonicspec.RirResult``. It is loaded on first use, so the command line stays quick.
"""

__version__ = "0.1.0.dev0"

__all__ = ["RirResult", "RirSettings", "Scene", "__version__", "compute_rir", "compute_rirs"]

_API = ("RirResult", "RirSettings", "Scene", "compute_rir", "compute_rirs")


def __getattr__(name: str):
    if name in _API:
        from sonicspec import api

        return getattr(api, name)
    raise AttributeError(f"module 'sonicspec' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])
