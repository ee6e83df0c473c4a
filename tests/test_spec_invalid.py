"""A table of invalid specs: each names the exact field and line, and the JSON Schema agrees."""

from __future__ import annotations

import json
from functools import lru_cache

import jsonschema
import pytest
import yaml
from spec_cases import BASE, CASES, apply

from sonicspec.errors import SpecError
from sonicspec.spec import validate_text
from sonicspec.spec.load import MAX_YAML_DEPTH, MAX_YAML_VALUES, format_path, parse_text
from sonicspec.spec.schema import json_schema


@lru_cache(maxsize=1)
def _validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json_schema())


def test_base_spec_is_valid_for_both() -> None:
    loaded, problems = validate_text(BASE, "base.yaml")
    assert loaded is not None, [p.format("base.yaml") for p in problems]
    assert not list(_validator().iter_errors(yaml.safe_load(BASE)))


def test_table_is_large_enough() -> None:
    assert len(CASES) >= 40
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_invalid_spec_names_field_and_line(case: tuple) -> None:
    cid, _, _, path, line, schema_rejects = case
    text = apply(case)
    loaded, problems = validate_text(text, "bad.yaml")
    assert loaded is None, f"{cid}: accepted"
    found = [(format_path(p.path), p.line) for p in problems if p.severity == "error"]
    assert (path, line) in found, f"{cid}: expected {path} at line {line}, got {found}"
    for p in problems:
        text_line = p.format("bad.yaml")
        assert text_line.startswith(f"bad.yaml:{p.line}:"), text_line
        assert "Traceback" not in text_line
    data = yaml.safe_load(text)
    schema_errors = list(_validator().iter_errors(data))
    if schema_rejects:
        assert schema_errors, f"{cid}: pydantic rejects but the JSON Schema accepts"
    else:
        assert not schema_errors, (
            f"{cid}: a semantic case the schema should accept; schema says "
            f"{[e.message for e in schema_errors]}")


def test_message_format_matches_the_documented_example() -> None:
    text = BASE.replace("size_m: [6, 5, 3]", "size_m: [8, -1, 3]")
    _, problems = validate_text(text, "specs/x.yaml")
    lines = [p.format("specs/x.yaml") for p in problems]
    assert ("specs/x.yaml:8:13: scenes[0].size_m: all values must be > 0 and <= 1000 "
            "(got [8, -1, 3])") in lines


@pytest.mark.parametrize(
    ("old", "new", "hint"),
    [
        ("seed: 1", "sed: 1", "did you mean 'seed'?"),
        ("kind: shoebox", "kind: shoebx", "did you mean 'shoebox'?"),
        ("walls: plaster_on_brick", "walls: plaster_on_brik", "did you mean 'plaster_on_brick'?"),
        ("library: sonicspec", "library: sonicsett", "did you mean 'sonicset'?"),
        ("background: noise}", "background: nois}", "did you mean 'noise'?"),
    ],
)
def test_did_you_mean(old: str, new: str, hint: str) -> None:
    _, problems = validate_text(BASE.replace(old, new, 1), "x.yaml")
    assert any(hint in p.message for p in problems), [p.message for p in problems]


def test_five_independent_errors_are_reported_at_once() -> None:
    text = (BASE.replace("seed: 1", "seed: -1")
            .replace("size_m: [6, 5, 3]", "size_m: [6, 0, 3]")
            .replace("  n: 4", "  n: 1")
            .replace("rays: 5000", "rays: 1")
            .replace("audio_format: flac", "audio_format: ogg"))
    _, problems = validate_text(text, "x.yaml")
    paths = {format_path(p.path) for p in problems}
    assert {"seed", "scenes[0].size_m", "microphone.n", "acoustics.rays",
            "outputs.audio_format"} <= paths
    assert [p.line for p in problems] == sorted(p.line for p in problems)


def test_several_semantic_errors_are_reported_at_once() -> None:
    text = (BASE.replace("id: ell", "id: room")
            .replace("walls: plaster_on_brick", "walls: nope")
            .replace("subtype: PCM_16", "subtype: FLOAT"))
    _, problems = validate_text(text, "x.yaml")
    paths = {format_path(p.path) for p in problems}
    assert {"scenes[1].id", "scenes[0].materials.walls", "outputs.subtype"} <= paths


def test_json_spec_gets_line_numbers_too() -> None:
    data = yaml.safe_load(BASE)
    data["seed"] = -5
    text = json.dumps(data, indent=2)
    _, problems = validate_text(text, "x.json")
    (p,) = [p for p in problems if p.path == ("seed",)]
    assert p.line == text.splitlines().index('  "seed": -5,') + 1


def test_suspicious_acoustics_are_warnings_that_name_the_field() -> None:
    """Valid but suspicious tracer settings load, with a warning on the field's line."""
    text = BASE.replace("  rays: 5000\n",
                        "  rays: 200\n  roulette_db: 90\n  horizontal_guiding: 0.8\n"
                        "  simplify_tolerance_m: 0.05\n")
    loaded, problems = validate_text(text, "w.yaml")
    assert loaded is not None, [p.format("w.yaml") for p in problems]
    warned = {format_path(w.path): w.format("w.yaml") for w in loaded.warnings}
    assert "Monte-Carlo noise" in warned["acoustics.rays"]
    assert "no effect" in warned["acoustics.roulette_db"]
    assert "w.yaml:" in warned["acoustics.roulette_db"]
    assert "too few plain directions" in warned["acoustics.horizontal_guiding"]
    assert "quarter of the wavelength" in warned["acoustics.simplify_tolerance_m"]


def billion_laughs(levels: int = 9, refs: int = 9) -> str:
    """The classic alias bomb: each level an anchored list of ``refs`` aliases of the last."""
    lines = ["sonicspec: 1", "a0: &a0 [" + ", ".join(["lol"] * refs) + "]"]
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * refs) + "]")
    lines.append(f"name: *a{levels}")
    return "\n".join(lines) + "\n"


def test_alias_bomb_is_refused_at_the_alias_that_overflows() -> None:
    # 9 levels of 9 aliases expand to 9^10 strings; counting stops at the alias that first
    # passes the bound (line 7: a5's aliases of a4, 9^5 strings each).
    with pytest.raises(SpecError, match=r"bomb.yaml:7:10: YAML aliases expand to more than "
                       r"100,000 values; each \*alias repeats"):
        parse_text(billion_laughs(), "bomb.yaml")


def test_aliases_within_the_bound_still_expand() -> None:
    text = "sonicspec: 1\nx: &x [1, 2, 3]\ny: [*x, *x]\nz: {<<: {a: 1}, b: *x}\n"
    data, smap = parse_text(text, "ok.yaml")
    assert data["y"] == [[1, 2, 3], [1, 2, 3]] and data["z"] == {"a": 1, "b": [1, 2, 3]}
    assert smap.values[("y", 1)] == (2, 4)  # an alias's values are located at their anchor


def test_many_plain_values_are_refused() -> None:
    text = "sonicspec: 1\nname: [" + ",".join(["1"] * (MAX_YAML_VALUES + 1)) + "]\n"
    with pytest.raises(SpecError, match=r"wide.yaml:2:\d+: expected at most 100,000 values in a "
                       r"spec, got more"):
        parse_text(text, "wide.yaml")


def test_recursive_alias_is_refused() -> None:
    with pytest.raises(SpecError, match=r"rec.yaml:2:11: alias \*x is used inside its own "
                       r"anchor &x; expected an alias of a value that is already complete"):
        parse_text("sonicspec: 1\na: &x [1, *x]\n", "rec.yaml")


@pytest.mark.parametrize("name", ["deep.yaml", "deep.json"])
def test_deep_nesting_is_refused(name: str) -> None:
    depth = 50 * MAX_YAML_DEPTH
    text = '{"sonicspec": 1, "name": ' + "[" * depth + "]" * depth + "}\n"
    with pytest.raises(SpecError, match=rf"{name}:1:\d+: expected at most 100 levels of "
                       r"nesting, got more"):
        parse_text(text, name)
