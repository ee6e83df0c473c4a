"""Spec versions and the migration registry that upgrades old specs to the current one.

A migration is a pure function on the parsed document (plain dicts and lists) from version
``n`` to ``n + 1``. Every released example spec is kept in ``tests/legacy_specs/`` and must
still load through the chain.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sonicspec.spec.dataset import SPEC_VERSION

Migration = Callable[[dict[str, Any]], dict[str, Any]]

MIGRATIONS: dict[int, Migration] = {}
"""``MIGRATIONS[n]`` upgrades a version-``n`` document to version ``n + 1``."""

OLDEST_VERSION = 1


def register_migration(from_version: int) -> Callable[[Migration], Migration]:
    """Decorator: register the upgrade from ``from_version`` to ``from_version + 1``."""

    def deco(fn: Migration) -> Migration:
        if from_version in MIGRATIONS:
            raise ValueError(f"a migration from version {from_version} is already registered")
        MIGRATIONS[from_version] = fn
        return fn

    return deco


def version_problem(version: Any) -> str | None:
    """Why ``version`` cannot be read, or None when it can."""
    if isinstance(version, bool) or not isinstance(version, int):
        return (
            f"expected the spec version as a whole number (e.g. sonicspec: {SPEC_VERSION}), "
            f"got {version!r}"
        )
    if version > SPEC_VERSION:
        from sonicspec import __version__

        return (
            f"spec version {version} is newer than this sonicspec ({__version__}) reads "
            f"(up to {SPEC_VERSION}); upgrade sonicspec"
        )
    if version < OLDEST_VERSION or any(v not in MIGRATIONS for v in range(version, SPEC_VERSION)):
        return f"unknown spec version {version}; known versions: {OLDEST_VERSION}..{SPEC_VERSION}"
    return None


def migrate(data: dict[str, Any]) -> dict[str, Any]:
    """Upgrade a document of any readable version to the current one."""
    version = data["sonicspec"]
    while version < SPEC_VERSION:
        data = MIGRATIONS[version](data)
        version += 1
        data["sonicspec"] = version
    return data
