"""Starting specs written by ``sonicspec init``; ``specs/`` holds the same files for reading."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from sonicspec.errors import SonicspecError
from sonicspec.spec.load import did_you_mean
from sonicspec.spec.schema import SCHEMA_FILENAME

PRESETS = ("array", "binaural", "demo", "sonicset", "sonicset_realistic", "sonicset_release")


def schema_line(target: str) -> str:
    """The modeline that makes YAML editors complete and check the file against the schema."""
    return f"# yaml-language-server: $schema={target}\n"


def template_body(preset: str) -> str:
    """The preset's text without the schema modeline."""
    if preset not in PRESETS:
        raise SonicspecError(
            f"preset: expected one of {', '.join(PRESETS)}, got {preset!r}"
            + did_you_mean(preset, PRESETS)
        )
    return resources.files(__name__).joinpath(f"{preset}.yaml").read_text(encoding="utf-8")


def packaged_schema_path() -> Path:
    """The copy of the JSON Schema installed with the package."""
    return Path(str(resources.files("sonicspec").joinpath("data", SCHEMA_FILENAME)))


def render_template(preset: str, output: Path | None = None) -> str:
    """The preset's text, with a modeline pointing at the installed schema.

    The path is relative to ``output`` when both are on one drive, so the pair can move.
    """
    schema = packaged_schema_path()
    target = str(schema)
    if output is not None:
        try:
            target = os.path.relpath(schema, Path(output).resolve().parent)
        except ValueError:
            target = str(schema)
    return schema_line(target) + template_body(preset)
