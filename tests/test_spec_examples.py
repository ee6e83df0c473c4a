"""Every example spec and preset validates; schema, templates and models stay in step."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from sonicspec.spec import DatasetSpec, load_spec, validate_text
from sonicspec.spec.schema import SCHEMA_FILENAME, json_schema, schema_text
from sonicspec.spec.templates import PRESETS, packaged_schema_path, schema_line, template_body

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "specs").glob("*.yaml"))
MODELINE = "# yaml-language-server: $schema=../schema/sonicspec-v1.schema.json"


def test_there_are_the_promised_examples() -> None:
    names = {p.stem for p in EXAMPLES}
    assert {"demo", "sonicset", "binaural", "array", "enhancement_static"} <= names


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_validates_and_agrees_with_schema(path: Path) -> None:
    loaded = load_spec(path)
    assert not loaded.warnings, [w.format(str(path)) for w in loaded.warnings]
    data = yaml.safe_load(path.read_text())
    jsonschema.Draft202012Validator(json_schema()).validate(data)
    assert path.read_text().splitlines()[0] == MODELINE


@pytest.mark.parametrize("preset", PRESETS)
def test_specs_folder_holds_the_presets_verbatim(preset: str) -> None:
    text = (ROOT / "specs" / f"{preset}.yaml").read_text()
    assert text == schema_line("../schema/sonicspec-v1.schema.json") + template_body(preset)


def test_checked_in_schema_is_up_to_date() -> None:
    """Regenerate with: sonicspec schema -o schema/sonicspec-v1.schema.json (and the copy in
    sonicspec/data/)."""
    assert (ROOT / "schema" / SCHEMA_FILENAME).read_text() == schema_text()
    assert packaged_schema_path().read_text() == schema_text()


def test_schema_is_deterministic_and_valid() -> None:
    assert schema_text() == schema_text()
    jsonschema.Draft202012Validator.check_schema(json_schema())


def _fields(schema: dict) -> list[tuple[str, dict]]:
    out = []
    for name, d in schema.get("$defs", {}).items():
        out += [(f"{name}.{k}", v) for k, v in d.get("properties", {}).items()]
    out += [(f"root.{k}", v) for k, v in schema["properties"].items()]
    return out


def test_every_field_has_a_description() -> None:
    missing = [name for name, prop in _fields(json_schema()) if not prop.get("description")]
    assert not missing, missing


def test_every_numeric_field_names_its_unit_or_is_a_count() -> None:
    """Floats carry a unit suffix (DESIGN.md §1) unless they are unitless by nature."""
    unitless = {"scale", "jitter_lu", "max_leak_fraction", "diffuse_fraction",
                "relative_humidity_pct", "temperature_c", "absorption", "scattering",
                "transmission", "scattering_override", "speed_of_sound_m_s", "ray_splitting",
                "horizontal_guiding", "probability"}
    suffixes = ("_m", "_m2", "_s", "_hz", "_db", "_lufs", "_deg", "_m_s", "_lu", "_pct", "_c",
                "_dbfs")
    bad = []
    for name, prop in _fields(json_schema()):
        field = name.split(".")[-1]
        types = {prop.get("type")} | {a.get("type") for a in prop.get("anyOf", [])}
        if "number" in types and field not in unitless and not field.endswith(suffixes):
            bad.append(name)
    assert not bad, bad


def test_defaults_follow_the_paper_recipe() -> None:
    text = "sonicspec: 1\nname: d\nscenes: [{kind: shoebox, id: r, size_m: [9, 9, 3]}]\n" \
           "corpora: {speech: {kind: generated}, noise: {kind: generated}, " \
           "music: {kind: generated}}\nsplits: {train: {groups: 1, scenes: [r]}}\n"
    loaded, problems = validate_text(text, "d.yaml")
    assert loaded is not None, problems
    spec: DatasetSpec = loaded.spec
    assert spec.sample_rate_hz == 16000
    assert spec.mixture.duration_s == 60 and spec.mixture.speakers == 3
    assert spec.mixture.utterances_per_speaker == (3, 5)
    assert (spec.mixture.noise_clips, spec.mixture.music_clips) == ((6, 8), (6, 8))
    lo = spec.mixture.loudness
    assert (lo.speech_lufs, lo.noise_lufs, lo.music_lufs) == (-17, -21, -24)
    assert spec.placement.source_start_distance_m == (1, 8)
    assert spec.trajectory.kind == "shortest_path"


def test_models_are_frozen() -> None:
    spec = load_spec(ROOT / "specs" / "demo.yaml").spec
    with pytest.raises(Exception, match="frozen"):
        spec.seed = 3  # type: ignore[misc]


def test_round_trip_through_json() -> None:
    spec = load_spec(ROOT / "specs" / "sonicset.yaml").spec
    again = DatasetSpec.model_validate(json.loads(spec.model_dump_json()))
    assert again == spec


def test_the_sonicset_preset_keeps_every_fsd50k_clip() -> None:
    """Issue 20: the paper does not drop FSD50K's speech-like labels; the default does."""
    spec = load_spec(ROOT / "specs" / "sonicset.yaml").spec
    assert spec.corpora.noise.exclude_labels == []
    assert "Speech" in type(spec.corpora.noise)(kind="fsd50k", root="x").exclude_labels
