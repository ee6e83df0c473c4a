"""Material libraries: the SonicSet table reproduced exactly, literature values, label rules."""

from __future__ import annotations

import json
import warnings
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry.materials import (
    LIBRARY_NAMES,
    Material,
    assign_materials,
    custom_material,
    load_library,
    mass_law_transmission,
    material_library,
    material_names,
)
from sonicspec.geometry.procedural import shoebox
from sonicspec.spec.materials import LIBRARY_FILES, MaterialsSpec, library_material_names
from sonicspec.units import OCTAVE_BANDS_HZ

REFERENCE = Path(__file__).resolve().parents[2] / "shared/reference/mp3d_material_config.json"
PACKAGED = json.loads(resources.files("sonicspec").joinpath(
    "data/materials/mp3d_material_config.json").read_text())


def test_sonicset_preset_reproduces_the_table_exactly() -> None:
    lib = load_library("sonicset")
    entries = PACKAGED["materials"]
    assert len(entries) == 30 and lib.names() == tuple(e["name"] for e in entries)
    for e in entries:
        m = lib.get(e["name"])
        for kind in ("absorption", "scattering", "transmission"):
            pairs = [x for f, v in zip(m.bands_hz, getattr(m, kind), strict=True) for x in (f, v)]
            assert pairs == pytest.approx(e[kind], abs=0), (e["name"], kind)


@pytest.mark.skipif(not REFERENCE.exists(), reason="shared/reference not beside the checkout")
def test_packaged_copy_equals_the_shared_reference() -> None:
    assert json.loads(REFERENCE.read_text()) == PACKAGED


@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("ceiling", "Acoustic Tile"),
        ("fireplace", "Brick"),
        ("zebra", "Default"),
    ],
)
def test_sonicset_label_rule(label: str, expected: str) -> None:
    assert load_library("sonicset").material_for_label(label) == expected


def test_sonicset_rule_counts_matches_and_breaks_ties_by_table_order() -> None:
    lib = load_library("sonicset")
    labelled = [(e["name"], e["labels"]) for e in PACKAGED["materials"] if e.get("labels")]
    # A category containing two labels of one material beats one label of an earlier one.
    for _, labels in labelled:
        if len(labels) >= 2:
            category = " ".join(labels[:2])
            counts = {n: sum(x.lower() in category.lower() for x in ls) for n, ls in labelled}
            best = max(counts.values())
            first = next(n for n, _ in labelled if counts[n] == best)
            assert lib.material_for_label(category) == first
            break
    else:
        pytest.skip("no material with two labels")


def test_default_library_is_complete_and_sourced() -> None:
    lib = load_library("sonicspec")
    assert len(lib.names()) >= 30
    for name in lib.names():
        m = lib.get(name)
        assert m.bands_hz == OCTAVE_BANDS_HZ
        assert m.source, name
        for kind in ("absorption", "scattering", "transmission"):
            assert all(0 <= v <= 1 for v in getattr(m, kind))


def test_spec_reads_the_same_material_names_as_the_libraries() -> None:
    # The spec validates names from the data files without importing geometry; both must
    # agree on every built-in library and its names.
    allowed = MaterialsSpec.model_fields["library"].annotation.__args__
    assert set(LIBRARY_FILES) == set(LIBRARY_NAMES) == set(allowed)
    for library in LIBRARY_NAMES:
        assert library_material_names(library) == material_names(library)


def test_mass_law_against_hand_values() -> None:
    # 4 mm glass, 10 kg/m²: TL(1 kHz) = 20 log10(1e4) - 47 = 33 dB.
    (tau,) = mass_law_transmission([1000.0], 10.0)
    assert 10 * np.log10(tau) == pytest.approx(-33.0)
    glass = load_library("sonicspec").get("glass_window")
    assert glass.transmission[3] == pytest.approx(tau)
    assert load_library("sonicspec").get("concrete_rough").transmission[0] < 1e-4


def test_every_mpcat40_category_maps_to_a_material() -> None:
    lib = load_library("sonicspec")
    table = resources.files("sonicspec").joinpath("data/mpcat40.tsv").read_text()
    names = [line.split("\t")[1] for line in table.splitlines()
             if line and not line.startswith("#") and line.split("\t")[0].isdigit()]
    assert len(names) >= 41
    for category in names:
        assert lib.material_for_label(category) in lib.names(), category
    assert lib.material_for_label("window") == "glass_window"
    assert lib.material_for_label("no such category") == "plaster_on_concrete"


def test_resampling_holds_ends_and_is_exact_on_table_points() -> None:
    tile = load_library("sonicset").get("Acoustic Tile")
    octave = tile.at_bands(OCTAVE_BANDS_HZ)
    assert octave.absorption[:6] == pytest.approx(tile.absorption)
    assert octave.absorption[6] == pytest.approx(tile.absorption[-1])  # 8 kHz holds 4 kHz
    flat = load_library("sonicset").get("Default").at_bands(OCTAVE_BANDS_HZ)
    assert flat.absorption == pytest.approx((0.1,) * 7)
    mid = tile.at_bands([np.sqrt(125.0 * 250.0)])
    assert mid.absorption[0] == pytest.approx(0.5 * (tile.absorption[0] + tile.absorption[1]))


def test_coefficients_and_custom_materials() -> None:
    foam = custom_material("foam", [0.8] * 7, [0.2] * 7, [0.0] * 7, OCTAVE_BANDS_HZ)
    lib = load_library("sonicspec").with_materials({"foam": foam})
    a, s, t = lib.coefficients(["foam", "marble"], OCTAVE_BANDS_HZ[:6])
    assert a.shape == s.shape == t.shape == (2, 6)
    assert a[0] == pytest.approx(0.8) and a[1, 0] == pytest.approx(0.01)
    assert "foam" not in material_names("sonicspec")


def test_errors_name_the_problem() -> None:
    with pytest.raises(GeometryError, match="did you mean 'plaster_on_brick'"):
        load_library("sonicspec").get("plaster_on_brik")
    with pytest.raises(GeometryError, match="did you mean 'sonicset'"):
        load_library("sonicsett")
    with pytest.raises(GeometryError, match="absorption values must lie in"):
        Material("x", (125.0,), (1.5,), (0.1,), (0.0,))
    with pytest.raises(GeometryError, match="expected 1 scattering values"):
        Material("x", (125.0,), (0.5,), (0.1, 0.2), (0.0,))


def test_custom_materials_join_a_library() -> None:
    lib = material_library("sonicset", {"panel": {"absorption": [0.2] * 7,
                                                  "scattering": [0.5] * 7,
                                                  "transmission": [0.0] * 7}})
    assert lib.name == "sonicset" and "panel" in lib.names() and "Default" in lib.names()
    assert lib.get("panel").absorption == (0.2,) * 7
    assert material_library("sonicspec") is load_library("sonicspec")


def labelled_box(*labels: str):
    """A 4 x 3 x 2.5 m box whose wall, floor and ceiling faces carry ``labels`` (in that
    order): wall area 35 m², floor and ceiling 12 m² each (59 m² in all)."""
    room = shoebox([4.0, 3.0, 2.5])
    order = [labels[("wall", "floor", "ceiling").index(name)] for name in room.labels]
    return room.replace(labels=tuple(order))


def test_labels_map_to_materials_without_a_word() -> None:
    mesh = labelled_box("walls", "floor", "ceiling")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = assign_materials(mesh, load_library("sonicspec"),
                               {"walls": "gypsum_board", "ceiling": "acoustic_ceiling_tile"})
    by_label = dict(zip(out.labels, (out.materials[out.face_material[out.face_label == i][0]]
                                     for i in range(len(out.labels))), strict=True))
    # "floor" is an mpcat40 category: the library's table maps it.
    assert by_label == {"walls": "gypsum_board", "floor": "parquet_on_concrete",
                        "ceiling": "acoustic_ceiling_tile"}


def test_faces_that_fall_back_to_the_default_material_are_named_with_their_area() -> None:
    """Issue 17: labels the map and the library do not know took the library's default in
    silence. The warning names each label, its share of the area and what it got."""
    mesh = labelled_box("walls", "floor", "roof")
    with pytest.warns(SonicspecWarning) as record:
        out = assign_materials(mesh, load_library("sonicspec"), {}, where="room.obj")
    (w,) = record
    text = str(w.message)
    assert text.startswith("room.obj: expected a material for every face label, got none for ")
    assert "'walls' (59.3 % of the area -> plaster_on_concrete)" in text
    assert "'roof' (20.3 % of the area -> plaster_on_concrete)" in text
    assert "the fallback of library 'sonicspec' covers 79.7 % of the area in all" in text
    assert "'floor'" not in text
    assert set(out.materials) == {"plaster_on_concrete", "parquet_on_concrete"}


def test_a_mesh_without_labels_falls_back_whole_unless_given_a_default() -> None:
    mesh = shoebox([4.0, 3.0, 2.5]).replace(face_label=None, labels=())
    with pytest.warns(SonicspecWarning, match=r"got none for faces without a label \(100.0 % "
                      r"of the area -> Default\)"):
        out = assign_materials(mesh, load_library("sonicset"))
    assert out.materials == ("Default",)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert assign_materials(mesh, load_library("sonicset"),
                                default="Carpet").materials == ("Carpet",)


def test_unlabelled_faces_and_unmatched_sonicset_labels_fall_back() -> None:
    mesh = labelled_box("unlabeled", "floor", "zzz")
    with pytest.warns(SonicspecWarning) as record:
        assign_materials(mesh, load_library("sonicset"))
    text = str(record[0].message)
    assert "faces without a label (59.3 % of the area -> Default)" in text
    assert "'zzz' (20.3 %" in text and "'floor'" not in text
    with pytest.warns(SonicspecWarning, match="'zzz'") as record:
        assign_materials(mesh, load_library("sonicset"), default="Carpet")
    assert "got none for faces without a label" not in str(record[0].message)
