"""Spec versions: the migration chain upgrades old documents; released specs keep loading."""

from __future__ import annotations

from pathlib import Path

import pytest

from sonicspec.spec import validate_file, validate_text, versions
from sonicspec.spec.dataset import SPEC_VERSION

ROOT = Path(__file__).resolve().parents[1]
LEGACY = sorted((ROOT / "tests" / "legacy_specs").rglob("*.yaml"))


def test_every_released_spec_still_loads() -> None:
    assert LEGACY, "tests/legacy_specs/ must hold the specs of every release"
    for path in LEGACY:
        loaded, problems = validate_file(path)
        assert loaded is not None, [p.format(str(path)) for p in problems]


def test_migration_chain_upgrades_old_documents(monkeypatch: pytest.MonkeyPatch) -> None:
    """A version-0 document with an old field name is upgraded through the registry."""
    monkeypatch.setattr(versions, "OLDEST_VERSION", 0)
    monkeypatch.setitem(versions.MIGRATIONS, 0, lambda d: {
        **{k: v for k, v in d.items() if k != "title"}, "name": d["title"]})
    text = (ROOT / "specs" / "demo.yaml").read_text().replace("sonicspec: 1", "sonicspec: 0")
    text = text.replace("name: demo", "title: demo")
    loaded, problems = validate_text(text, "old.yaml")
    assert loaded is not None, [p.format("old.yaml") for p in problems]
    assert loaded.spec.name == "demo" and loaded.spec.sonicspec == SPEC_VERSION


def test_registering_twice_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(versions, "MIGRATIONS", {})
    versions.register_migration(0)(lambda d: d)
    with pytest.raises(ValueError, match="already registered"):
        versions.register_migration(0)(lambda d: d)


def test_version_without_migration_path_is_unknown() -> None:
    assert "unknown spec version 0" in versions.version_problem(0)
    assert versions.version_problem(SPEC_VERSION) is None
    assert "whole number" in versions.version_problem("1")
    assert "whole number" in versions.version_problem(True)
