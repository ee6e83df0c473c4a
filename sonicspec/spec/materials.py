"""Materials: a built-in library plus user-defined materials.

The spec knows the built-in libraries as data: their material names come from the packaged JSON
files (``sonicspec/data/materials/``), the same files the geometry library builds its materials
from, so validating a spec imports no geometry (nor numpy).
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Literal

from pydantic import Field

from sonicspec.spec.base import BandCoefficients, SpecModel


class CustomMaterialSpec(SpecModel):
    """A material defined in the spec, per octave band 125 Hz–8 kHz (one value: all bands)."""

    absorption: BandCoefficients = Field(
        description="Energy absorption coefficient per band, 0–1 (random incidence)."
    )
    scattering: BandCoefficients = Field(
        0.1, description="Scattering coefficient per band (ISO 17497-1), 0–1."
    )
    transmission: BandCoefficients = Field(
        0.0, description="Energy transmission coefficient per band, 0–1 (1: acoustically open)."
    )
    description: str = Field("", description="Free text: what the material is, its source.")


LIBRARY_FILES = {"sonicspec": "sonicspec.json", "sonicset": "mp3d_material_config.json"}
"""The packaged data file of each built-in material library."""


@cache
def library_material_names(library: str) -> tuple[str, ...]:
    """The material names of a built-in library, in the order of its data file."""
    text = (resources.files("sonicspec").joinpath("data", "materials", LIBRARY_FILES[library])
            .read_text("utf-8"))
    return tuple(entry["name"] for entry in json.loads(text)["materials"])


class MaterialsSpec(SpecModel):
    """Which material library names resolve against, and materials the spec adds."""

    library: Literal["sonicspec", "sonicset"] = Field(
        "sonicspec",
        description="Built-in library: 'sonicspec' (7 octave bands, literature values) or "
        "'sonicset' (SonicSet's Matterport3D table and label rule, reproduced exactly).",
    )
    custom: dict[str, CustomMaterialSpec] = Field(
        default_factory=dict,
        description="User-defined materials by name; a name equal to a library material "
        "replaces it.",
    )
    label_materials: dict[str, str] = Field(
        default_factory=dict,
        description="Semantic label -> material name for every mesh scene (a scene's own "
        "map wins).",
    )
    scattering_override: BandCoefficients | None = Field(
        None,
        description="Scattering coefficient per octave band 125 Hz–8 kHz (ISO 17497-1), 0–1 "
        "(one value: every band), given to every surface in place of its material's own; "
        "absorption and transmission stay the material's. null (the default): each "
        "material's measured scattering. 1.0 makes every reflection fully diffuse (Lambert), "
        "which is what RLR — the engine SonicSet was rendered with — computes whatever its "
        "material table says: with SonicSet's table (scattering 0.10–0.15 on walls, carpet "
        "and furniture) sonicspec's T30 in a furnished apartment is then RLR's, against "
        "about 2.3x RLR's with the measured values (bench/bench_sonicset_scattering.py). "
        "The 'sonicset' presets set 1.0 to give SonicSet's reverberation; leave it null "
        "for realistic reverberation.",
    )
