"""Error hierarchy.

Every error sonicspec raises for bad input derives from :class:`SonicspecError`, which is
also a :class:`ValueError`, so callers that only know the builtins still catch it.
"""

from __future__ import annotations


class SonicspecError(ValueError):
    """Base class of every error sonicspec raises on purpose."""


class SpecError(SonicspecError):
    """A spec file is unreadable or invalid.

    ``problems`` holds every :class:`~sonicspec.spec.load.Problem` found, so a caller can
    show all of them at once instead of the first.
    """

    def __init__(self, message: str, problems: list | None = None) -> None:
        super().__init__(message)
        self.problems = list(problems or [])


class CompileError(SonicspecError):
    """A valid spec cannot be turned into a plan (e.g. a glob matches no scene)."""


class GeometryError(SonicspecError):
    """A scene cannot be built, imported, repaired or navigated as asked."""


class PlacementError(GeometryError):
    """Positions satisfying the placement rules could not be found."""


class AcousticsError(SonicspecError):
    """A simulation was asked for something it cannot compute."""


class AudioError(SonicspecError):
    """An audio input (corpus file, track) is missing, unreadable or unusable."""


class CorpusError(AudioError):
    """A corpus is missing, malformed, unreadable or too small for what is asked of it."""


class StageError(SonicspecError):
    """A pipeline stage failed; ``key`` names the job's content key."""

    def __init__(self, message: str, key: str | None = None) -> None:
        super().__init__(message if key is None else f"job {key[:12]}: {message}")
        self.key = key


class StoreError(SonicspecError):
    """The artifact store is missing, corrupt or cannot be written."""


class SonicspecWarning(UserWarning):
    """Valid but suspicious input: the result may not be what was meant."""
