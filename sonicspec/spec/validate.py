"""Load a spec file end to end: parse, check the version, validate, run the semantic checks."""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path

from pydantic import ValidationError

from sonicspec.errors import SpecError
from sonicspec.spec.checks import check_files, check_spec
from sonicspec.spec.dataset import SPEC_VERSION, DatasetSpec
from sonicspec.spec.load import (
    LoadedSpec,
    Problem,
    SourceMap,
    parse_text,
    problems_from_validation,
    sort_problems,
)
from sonicspec.spec.scene_file import SceneFileSpec
from sonicspec.spec.versions import migrate, version_problem


def _locate(problems: list[Problem], smap: SourceMap) -> list[Problem]:
    out = []
    for p in problems:
        if p.line is None:
            where = smap.locate(p.path)
            if where is not None:
                p = Problem(p.path, p.message, where[0], where[1], p.severity)
        out.append(p)
    return out


def locate_in_file(problems: list[Problem], source: str | Path) -> list[Problem]:
    """``problems`` (paths into the spec at ``source``) with line and column, sorted; as given
    if the file cannot be read or parsed. For checks run after loading (preflight)."""
    try:
        _, smap = parse_text(Path(source).read_text(encoding="utf-8"), str(source))
    except (OSError, UnicodeDecodeError, SpecError):
        return sort_problems(problems)
    return sort_problems(_locate(problems, smap))


def validate_text(
    text: str, source: str, base_dir: Path | None = None, *, files: bool = False,
    cli_outputs: Collection[str] = (),
) -> tuple[LoadedSpec | None, list[Problem]]:
    """Validate spec text; returns the loaded spec (None if invalid) and every problem found.

    ``source`` names the text in messages (usually the file path); ``base_dir`` anchors the
    relative paths inside the spec (default: the folder of ``source``). ``cli_outputs``: the
    output folders the command line chooses (see :func:`~sonicspec.spec.checks.check_spec`).
    """
    base = Path(base_dir) if base_dir is not None else Path(source).parent
    try:
        data, smap = parse_text(text, source)
    except SpecError as exc:
        return None, list(exc.problems)
    if "sonicspec" not in data:
        return None, [
            Problem(
                ("sonicspec",),
                f"required field missing: put 'sonicspec: {SPEC_VERSION}' at the top of the file",
                1,
                1,
            )
        ]
    why = version_problem(data["sonicspec"])
    if why is not None:
        where = smap.locate(("sonicspec",)) or (1, 1)
        return None, [Problem(("sonicspec",), why, *where)]
    data = migrate(data)
    try:
        spec = DatasetSpec.model_validate(data)
    except ValidationError as exc:
        return None, sort_problems(problems_from_validation(exc, DatasetSpec, data, smap))
    problems = check_spec(spec, cli_outputs=cli_outputs, base_dir=base)
    if files:
        problems += check_files(spec, base)
    problems = sort_problems(_locate(problems, smap))
    errors = [p for p in problems if p.severity == "error"]
    if errors:
        return None, problems
    warnings = tuple(p for p in problems if p.severity == "warning")
    return LoadedSpec(spec=spec, source=source, base_dir=base, warnings=warnings), problems


MAX_SPEC_BYTES = 4 * 1024 * 1024
"""Largest spec file read (4 MiB). Real specs are a few KB (specs/sonicset.yaml, 90 scenes by
glob, is 2.9 KB); the bound keeps a wrong file (a mesh, a log, a generated dump) from costing
minutes and gigabytes of parsing. The file's size is checked before it is read."""


def _mib(n: int) -> str:
    return f"{n / (1024 * 1024):.1f} MiB ({n:,} bytes)"


def validate_file(
    path: str | Path, *, files: bool = False, cli_outputs: Collection[str] = ()
) -> tuple[LoadedSpec | None, list[Problem]]:
    """Validate the spec file at ``path`` (see :func:`validate_text`)."""
    path = Path(path)
    source = str(path)
    limit = f"expected a spec file of at most {_mib(MAX_SPEC_BYTES)}, got"
    hint = "real specs are a few KB; is this the right file?"
    try:
        with path.open(encoding="utf-8") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > MAX_SPEC_BYTES:
                return None, [Problem((), f"{limit} {_mib(size)}; {hint}")]
            # At most one character past the bound: a file that grows while it is read, or
            # a device that reports size 0, is still not read whole.
            text = fh.read(MAX_SPEC_BYTES + 1)
        if len(text) > MAX_SPEC_BYTES:
            return None, [Problem((), f"{limit} more; {hint}")]
    except FileNotFoundError:
        return None, [Problem((), "no such file")]
    except IsADirectoryError:
        return None, [Problem((), "is a folder, not a spec file")]
    except UnicodeDecodeError as exc:
        return None, [Problem((), f"not UTF-8 text (byte {exc.start}); save the spec as UTF-8")]
    except OSError as exc:
        return None, [Problem((), f"cannot be read: {exc.strerror}")]
    return validate_text(text, source, path.parent, files=files, cli_outputs=cli_outputs)


def validate_scene_file(path: str | Path) -> tuple[SceneFileSpec | None, list[Problem]]:
    """Validate a scene file (:mod:`sonicspec.spec.scene_file`): the model, or None and the
    problems, located in the file. A file without a ``scene`` is named as such."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        return None, [Problem((), f"cannot be read: {getattr(exc, 'strerror', exc)}")]
    try:
        data, smap = parse_text(text, str(path))
    except SpecError as exc:
        return None, list(exc.problems)
    if not isinstance(data, dict) or "scene" not in data:
        return None, [Problem(("scene",), "required field missing: a scene file holds a "
                              "'scene' (or give a dataset spec, with 'sonicspec: 1')", 1, 1)]
    try:
        return SceneFileSpec.model_validate(data), []
    except ValidationError as exc:
        return None, sort_problems(problems_from_validation(exc, SceneFileSpec, data, smap))


def load_spec(path: str | Path, *, files: bool = False) -> LoadedSpec:
    """Load and validate a spec file, raising :class:`SpecError` with every problem if invalid."""
    loaded, problems = validate_file(path, files=files)
    if loaded is None:
        errors = [p for p in problems if p.severity == "error"]
        raise SpecError("\n".join(p.format(str(path)) for p in errors), errors)
    return loaded
