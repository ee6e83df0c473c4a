"""``materials.scattering_override``: every surface's scattering replaced (issue 30).

RLR, the engine SonicSet was rendered with, makes every reflection diffuse whatever its material
table says; the ``sonicset`` presets set ``scattering_override: 1.0`` so that their
reverberation is SonicSet's, and a realistic spec keeps the table's measured scattering.
"""

from __future__ import annotations

import numpy as np
import pytest

import sonicspec as ss
from sonicspec.acoustics.theory import eyring_t60
from sonicspec.errors import GeometryError
from sonicspec.geometry.materials import load_library, material_library
from sonicspec.plan.params import MaterialTable
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.spec.scene import ShoeboxSceneSpec
from sonicspec.spec.templates import template_body

SIZE_M = (7.0, 5.0, 2.7)
ROOM = ShoeboxSceneSpec(kind="shoebox", id="room", size_m=SIZE_M, materials={
    "walls": "Gypsum Board", "floor": "Carpet", "ceiling": "Acoustic Tile"})


def test_the_field_broadcasts_one_value_and_defaults_to_the_measured_scattering() -> None:
    assert MaterialsSpec().scattering_override is None
    assert MaterialsSpec(scattering_override=1.0).scattering_override == (1.0,) * 7
    assert MaterialsSpec(scattering_override=[0.5] * 7).scattering_override == (0.5,) * 7
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        MaterialsSpec(scattering_override=1.5)
    with pytest.raises(ValueError, match="one value or 7 values"):
        MaterialsSpec(scattering_override=[1.0, 1.0])


def test_the_library_replaces_scattering_only() -> None:
    table = load_library("sonicset")
    diffuse = material_library("sonicset", scattering=[1.0] * 7)
    assert diffuse.names() == table.names()
    for name in table.names():
        a, b = table.get(name), diffuse.get(name)
        assert b.scattering == (1.0,) * len(a.bands_hz)
        assert (b.absorption, b.transmission, b.bands_hz) == (a.absorption, a.transmission,
                                                              a.bands_hz)
    # seven octave-band values land on a material's own bands (SonicSet's: 125 Hz-4 kHz)
    ramp = material_library("sonicset", scattering=np.linspace(0.1, 0.7, 7))
    assert ramp.get("Carpet").scattering == pytest.approx((0.1, 0.2, 0.3, 0.4, 0.5, 0.6))
    # custom materials are overridden too
    custom = {"foam": {"absorption": [0.8] * 7, "scattering": [0.1] * 7,
                       "transmission": [0.0] * 7}}
    assert material_library("sonicspec", custom, [1.0] * 7).get("foam").scattering == (1.0,) * 7
    with pytest.raises(GeometryError, match=r"scattering: expected 7 values in \[0, 1\]"):
        table.with_scattering([1.0, 1.0])


def test_the_sonicset_presets_give_sonicsets_reverberation() -> None:
    import yaml

    for preset in ("sonicset", "sonicset_release"):
        doc = yaml.safe_load(template_body(preset))
        assert MaterialsSpec(**doc["materials"]).scattering_override == (1.0,) * 7, preset
        assert "every surface fully diffuse, as RLR renders it" in doc["description"]


def test_rir_params_leave_the_field_out_at_its_default() -> None:
    # the rir keys of every spec that does not set it stay as they were
    plain = MaterialTable(library="sonicset", custom={})
    assert plain.model_dump(mode="json") == {"library": "sonicset", "custom": {}}
    diffuse = MaterialTable(library="sonicset", custom={}, scattering_override=1.0)
    assert diffuse.model_dump(mode="json")["scattering_override"] == [1.0] * 7
    assert MaterialTable.model_validate(diffuse.model_dump(mode="json")) == diffuse
    assert MaterialTable.model_validate(plain.model_dump(mode="json")) == plain


def _t30(scattering_override) -> np.ndarray:
    scene = ss.Scene.from_spec(ROOM, MaterialsSpec(library="sonicset",
                                                   scattering_override=scattering_override))
    settings = ss.RirSettings(rays=2000, image_source_order=1, sample_rate_hz=16000)
    return np.mean([ss.compute_rir(scene, [1.5, 1.2, 1.5], [5.0, 3.5, 1.2], settings,
                                   seed=seed).expected["t30_s"] for seed in range(2)], axis=0)


def test_full_scattering_shortens_the_decay_to_the_diffuse_fields() -> None:
    """Gypsum walls that absorb 4-7 % between a carpet and an absorbing ceiling: with the
    table's scattering (0.10-0.15 on the walls) rays keep bouncing between the walls, away from
    the absorbing floor and ceiling, and the decay is long; with every surface fully diffuse the
    field mixes and decays as Eyring's formula says (the diffuse field's reference)."""
    measured, diffuse = _t30(None), _t30(1.0)
    table = load_library("sonicset")
    walls = 2 * (SIZE_M[0] + SIZE_M[1]) * SIZE_M[2]
    floor = SIZE_M[0] * SIZE_M[1]

    def absorption(name: str) -> np.ndarray:
        return np.array(table.get(name).absorption)

    alpha = ((walls * absorption("Gypsum Board")
              + floor * (absorption("Carpet") + absorption("Acoustic Tile")))
             / (walls + 2 * floor))
    eyring = eyring_t60(float(np.prod(SIZE_M)), walls + 2 * floor, alpha)
    assert diffuse == pytest.approx(eyring, rel=0.15)
    # the direction: measured scattering decays slower in every band, by far above 250 Hz
    assert np.all(measured > diffuse)
    assert np.all(measured[1:] > 1.4 * diffuse[1:]), (measured, diffuse)
