"""The documentation site (issue 29): generated references complete, examples that run, a
strict build, and a README that says where everything is.

The spec and CLI references are generated at build time (``docs/hooks.py``); these tests walk
the models and the parser on their own and look for every field and command in the generated
Markdown. Every ```python block of ``README.md`` and ``docs/`` runs here, from the repository's
root, unless the line before it is ``<!-- docs-test: skip REASON -->``; a reason that names
another test is checked to be true (that test runs that very block).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import re
import subprocess
import sys
import typing
from pathlib import Path

import pytest
from build_cases import readme_python
from pydantic import BaseModel

from sonicspec.cli import build_parser
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.reference import spec_reference, unit_of
from sonicspec.spec.scene_file import SceneFileSpec

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.rglob("*.md"))


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


HOOKS = _hooks()


# --- the spec reference ---------------------------------------------------------------------


def _models(root: type[BaseModel]) -> dict[str, type[BaseModel]]:
    """Every model reachable from ``root`` through its fields' annotations (no schema)."""
    found: dict[str, type[BaseModel]] = {}
    todo: list[object] = [root]
    while todo:
        tp = todo.pop()
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            if tp.__name__ not in found:
                found[tp.__name__] = tp
                todo += [info.annotation for info in tp.model_fields.values()]
            continue
        todo += list(typing.get_args(tp))
    return found


def _section(text: str, model: str) -> str:
    found = re.search(rf"^### {model} \{{#{model.lower()}\}}\n(.*?)(?=^##)", text + "\n##",
                      re.S | re.M)
    assert found, f"spec reference: no section for {model}"
    return found.group(1)


def _row(section: str, field: str) -> list[str]:
    found = re.search(rf"^\| `{field}` \|(.*)\|$", section, re.M)
    assert found, f"spec reference: no row for {field}"
    return [c.strip() for c in re.split(r"(?<!\\)\|", found.group(1))]


def test_every_spec_field_is_in_the_spec_reference() -> None:
    text = spec_reference()
    models = {**_models(DatasetSpec), **_models(SceneFileSpec)}
    assert len(models) > 40
    fields = 0
    for name, model in models.items():
        section = _section(text, name)
        for field in model.model_fields:
            _row(section, field)
            fields += 1
    assert fields > 250


def test_the_spec_reference_states_type_unit_default_and_range() -> None:
    text = spec_reference()
    size = _row(_section(text, "ShoeboxSceneSpec"), "size_m")
    assert size[:3] == ["[number, number, number]", "m", "required"]
    assert "> 0 and ≤ 1000" in size[3] and "metres" in size[3]
    rays = _row(_section(text, "AcousticsSpec"), "rays")
    assert rays[2] == "`" + str(DatasetSpec.model_fields["acoustics"].default_factory().rays) + "`"
    guiding = _row(_section(text, "AcousticsSpec"), "horizontal_guiding")
    assert "≥ 0 and &lt; 1" in guiding[3]
    lufs = _row(_section(text, "LoudnessSpec"), "speech_lufs")
    assert lufs[1:3] == ["LUFS", "`-17.0`"]
    mic = _row(_section(text, "DatasetSpec"), "microphone")
    assert "[mono](#monomicspec)" in mic[0] and mic[2] == '`{"kind": "mono"}`'
    # a union of models links every member's section, and every link has its section
    for anchor in set(re.findall(r"\]\(#([a-z0-9]+)\)", text)):
        assert f"{{#{anchor}}}" in text, anchor
    assert [unit_of(f) for f in ("speed_of_sound_m_s", "size_m", "peak_limit_dbfs",
                                 "jitter_lu", "yaw_deg", "rays")] == [
        "m/s", "m", "dBFS", "LU", "degrees", ""]


def test_the_spec_page_is_generated_not_written() -> None:
    page = (DOCS / "reference" / "spec.md").read_text(encoding="utf-8")
    assert "<!-- generated: spec -->" in page and "| field |" not in page
    assert HOOKS.expand(page).count("### DatasetSpec {#datasetspec}") == 1
    with pytest.raises(ValueError, match="unknown generated block 'nope'"):
        HOOKS.expand("<!-- generated: nope -->")


# --- the CLI reference ----------------------------------------------------------------------


def _walk(parser: argparse.ArgumentParser, prefix: str = "") -> list[tuple[str, list[str]]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                full = f"{prefix} {name}".strip()
                options = [o for a in sub._actions for o in a.option_strings
                           if not isinstance(a, argparse._HelpAction)]
                out.append((full, options))
                out += _walk(sub, full)
    return out


def test_every_command_and_option_is_in_the_cli_page() -> None:
    page = (DOCS / "reference" / "cli.md").read_text(encoding="utf-8")
    assert "<!-- generated: cli -->" in page
    text = HOOKS.expand(page)
    commands = _walk(build_parser())
    names = [c for c, _ in commands]
    assert {"validate", "build", "rir", "scene", "scene inspect", "evaluate", "export",
            "report", "verify"} <= set(names)
    for command, options in commands:
        heading = "###" if " " in command else "##"
        found = re.search(rf"^{heading} sonicspec {command} \{{#[a-z-]+\}}\n(.*?)(?=^##|\Z)",
                          text, re.S | re.M)
        assert found, f"cli page: no section for {command!r}"
        for option in options:
            assert f"`{option}" in found.group(1), f"cli page: {command} {option}"
    assert text.count("```text\nusage: sonicspec") == len(commands) + 1


# --- the code blocks ------------------------------------------------------------------------


def _python_blocks() -> list[tuple[str, int, str, str | None]]:
    """(file, line, code, skip reason) of every ```python block of the README and the docs."""
    out = []
    for path in [ROOT / "README.md", *PAGES]:
        lines = path.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            if line.strip() != "```python":
                continue
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            marker = re.fullmatch(r"<!-- docs-test: skip (.*) -->", lines[i - 1].strip())
            out.append((str(path.relative_to(ROOT)), i + 1, "\n".join(lines[i + 1:end]) + "\n",
                        marker.group(1).strip() if marker else None))
    return out


BLOCKS = _python_blocks()


def test_the_blocks_are_found_and_most_run() -> None:
    files = {f for f, *_ in BLOCKS}
    assert {"README.md", "docs/guide/rir.md", "docs/guide/data.md",
            "docs/guide/spec.md"} <= files
    assert sum(1 for *_, reason in BLOCKS if reason is None) >= 2
    for file, line, code, reason in BLOCKS:
        if reason is None:
            continue
        where = f"{file}:{line}"
        assert len(reason) > 10, f"{where}: a skipped block states why"
        if "tests/test_api.py" in reason:  # test_api runs the README's block
            assert code == readme_python(), f"{where}: not the block test_api runs"
        elif "tests/test_dataload.py" in reason:  # test_dataload runs data.md's blocks
            assert file == "docs/guide/data.md", where
        elif "tests/test_pipeline_augment.py" in reason:  # it runs the loader's block
            assert file == "docs/guide/augmentation.md", where
        else:
            pytest.fail(f"{where}: a skipped block must name the test that runs it")


@pytest.mark.parametrize(("file", "line", "code", "reason"), BLOCKS,
                         ids=[f"{f}:{n}" for f, n, *_ in BLOCKS])
def test_python_block_runs(file: str, line: int, code: str, reason: str | None,
                           monkeypatch) -> None:
    if reason is not None:
        pytest.skip(reason)
    monkeypatch.chdir(ROOT)
    exec(compile(code, f"{file}:{line}", "exec"), {"__name__": "__docs__"})


# --- the YAML examples --------------------------------------------------------------------


def _yaml_blocks() -> list[tuple[str, int, str]]:
    out = []
    for path in PAGES:
        text = path.read_text(encoding="utf-8")
        for found in re.finditer(r"^```yaml\n(.*?)^```", text, re.S | re.M):
            line = text[:found.start()].count("\n") + 1
            out.append((str(path.relative_to(ROOT)), line, found.group(1)))
    return out


YAML_BLOCKS = _yaml_blocks()


@pytest.mark.parametrize(("file", "line", "text"), YAML_BLOCKS,
                         ids=[f"{f}:{n}" for f, n, _ in YAML_BLOCKS])
def test_yaml_example_validates(file: str, line: int, text: str) -> None:
    """A whole spec validates as it is; a fragment (some top-level sections) validates in
    place of the demo spec's own sections."""
    import yaml

    from sonicspec.spec import validate_text

    fragment = yaml.safe_load(text)
    assert isinstance(fragment, dict), f"{file}:{line}: not a mapping"
    if "sonicspec" in fragment:
        spec = fragment
    else:
        spec = yaml.safe_load((ROOT / "specs" / "demo.yaml").read_text(encoding="utf-8"))
        unknown = set(fragment) - set(DatasetSpec.model_fields)
        assert not unknown, f"{file}:{line}: not spec sections: {sorted(unknown)}"
        spec.update(fragment)
    loaded, problems = validate_text(yaml.safe_dump(spec), str(ROOT / "specs" / "x.yaml"))
    errors = [p for p in problems if p.severity == "error"]
    assert loaded is not None and not errors, f"{file}:{line}: {errors}"


# --- names the pages give -------------------------------------------------------------------


def _named() -> tuple[set[str], set[str]]:
    """Repository paths and ``sonicspec.`` dotted names in the code spans of the pages."""
    paths, dotted = set(), set()
    for path in [ROOT / "README.md", *PAGES]:
        for code in re.findall(r"`([^`\n]+)`", path.read_text(encoding="utf-8")):
            paths |= set(re.findall(r"(?<![\w/.-])((?:sonicspec|bench|tests|specs|workflow|"
                                    r"schema|docs)/[\w/.\-]*\w)", code))
            dotted |= set(re.findall(r"(?<![\w/.])(sonicspec(?:\.\w+)+)", code))
    return {p for p in paths if not p.startswith("specs/out")}, dotted


def test_the_files_and_modules_the_pages_name_exist() -> None:
    """A page naming a module that moved (say, an acoustics module regrouped) fails here:
    strict mode checks links, not the paths and names written in code spans."""
    paths, dotted = _named()
    assert {"sonicspec.acoustics.moving", "sonicspec.acoustics.theory"} <= dotted
    assert {"sonicspec/audio/render.py", "bench/RESULTS.md"} <= paths
    assert [p for p in sorted(paths) if not (ROOT / p).exists()] == []
    missing = []
    for name in sorted(dotted):
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):  # the longest importable prefix, then attributes
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                missing.append(name)
            break
        else:
            missing.append(name)
    assert missing == []


# --- the README and the build ---------------------------------------------------------------


def test_the_readme_is_short_and_says_where_everything_is() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    commands = [line for line in text.splitlines() if line.startswith("apt-get")]
    assert len(commands) == 2
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()[-1]
    assert commands[1] == ci  # the README's test command is exactly what CI runs
    started = (DOCS / "getting-started.md").read_text(encoding="utf-8").splitlines()
    assert [line for line in started if line.startswith("apt-get")] == commands
    assert "mkdocs build --strict && python -m pytest" in ci
    for needle in ("docs/reference/spec.md", "docs/getting-started.md", "## Citing",
                   "@inproceedings{li2025sonicsim", "docs/report.png"):
        assert needle in text, needle
    for link in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
        assert (ROOT / link).exists(), f"README.md: broken link {link}"
    bib = re.search(r"^```bibtex\n(.*?)^```", text, re.S | re.M)
    assert bib and bib.group(1) == (DOCS / "citation.bib").read_text(encoding="utf-8")
    assert '--8<-- "docs/citation.bib"' in (DOCS / "index.md").read_text(encoding="utf-8")


def test_mkdocs_builds_in_strict_mode(tmp_path: Path) -> None:
    """Broken links, anchors and references fail the build (a few seconds)."""
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet",
                           "-f", str(ROOT / "mkdocs.yml"), "-d", str(tmp_path / "site")],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    spec = (tmp_path / "site" / "reference" / "spec.html").read_text(encoding="utf-8")
    assert 'id="acousticsspec"' in spec and "max_rir_length_s" in spec
    api = (tmp_path / "site" / "reference" / "api.html").read_text(encoding="utf-8")
    assert "compute_rir" in api and "SonicspecDataset" in api and "wedge_diffraction_ir" in api
    assert (tmp_path / "site" / "figures" / "half_plane_diffraction.png").is_file()
    bench = (tmp_path / "site" / "benchmarks.html").read_text(encoding="utf-8")
    assert "bench_rlr.py" in bench  # bench/RESULTS.md itself, included
