"""Acoustic materials: the built-in libraries, user materials, and face labels -> materials.

Two libraries ship as data (``sonicspec/data/materials/``):

* ``sonicspec`` (default): 36 materials on the seven octave bands 125 Hz–8 kHz. Absorption is
  the random-incidence coefficient from Vorländer (2008), *Auralization*, Appendix A; scattering
  follows the material's surface class (smooth, textured, furniture, upholstery), with the
  furniture and upholstery classes from the same book's scattering tables; transmission comes
  from the field-incidence mass law, ``TL = 20 log10(f m) - 47 dB`` with the material's
  surface density ``m`` (Long, *Architectural Acoustics*, 2014), or is given directly where the
  mass law does not apply (porous fabrics, open foam). Every entry names its source. Matterport3D
  categories (mpcat40) map to materials through ``mpcat40_to_sonicspec.json``.
* ``sonicset``: SonicSet's own table (``mp3d_material_config.json``, from the SoundSpaces 2.0 /
  SonicSim releases, CC BY), reproduced exactly — the same 30 materials, names and
  (frequency, coefficient) pairs — with its label rule: a face's category takes the material
  whose ``labels`` match it most often (a material label matches when it is a substring of the
  category name, case-insensitively); ties go to the material listed first; no match gives
  ``Default``.

Coefficients are resampled to the bands a simulation uses by :meth:`Material.at_bands`: linear
interpolation in log-frequency between the tabulated points, the end values held outside them
(SonicSet's table stops at 4 kHz, so its 8 kHz band takes the 4 kHz value; its ``Default`` has
only 20 Hz and 20 kHz points, i.e. flat).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry.mesh import UNLABELED, SceneMesh
from sonicspec.units import OCTAVE_BANDS_HZ

LIBRARY_NAMES = ("sonicspec", "sonicset")
SONICSET_DEFAULT = "Default"


def _hint(word: str, options: Sequence[str]) -> str:
    match = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f"; did you mean {match[0]!r}?" if match else ""


def mass_law_transmission(frequencies_hz: Sequence[float], surface_density_kg_m2: float
                          ) -> tuple[float, ...]:
    """Energy transmission coefficient of a single leaf by the field-incidence mass law."""
    out = []
    for f in frequencies_hz:
        tl_db = 20.0 * math.log10(f * surface_density_kg_m2) - 47.0
        out.append(min(1.0, 10.0 ** (-max(tl_db, 0.0) / 10.0)))
    return tuple(out)


@dataclass(frozen=True)
class Material:
    """Per-band energy coefficients of one material (absorption, scattering, transmission)."""

    name: str
    bands_hz: tuple[float, ...]
    absorption: tuple[float, ...]
    scattering: tuple[float, ...]
    transmission: tuple[float, ...]
    description: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        n = len(self.bands_hz)
        if n == 0 or any(b <= 0 for b in self.bands_hz) or list(self.bands_hz) != sorted(
                self.bands_hz):
            raise GeometryError(f"material {self.name!r}: expected increasing positive band "
                                f"frequencies, got {list(self.bands_hz)}")
        for kind in ("absorption", "scattering", "transmission"):
            values = getattr(self, kind)
            if len(values) != n:
                raise GeometryError(f"material {self.name!r}: expected {n} {kind} values, one "
                                    f"per band, got {len(values)}")
            if not all(0.0 <= v <= 1.0 for v in values):
                raise GeometryError(f"material {self.name!r}: {kind} values must lie in [0, 1], "
                                    f"got {list(values)}")

    def at_bands(self, bands_hz: Sequence[float]) -> Material:
        """The material on other bands (log-frequency interpolation, end values held)."""
        src = np.log(np.asarray(self.bands_hz, dtype=np.float64))
        dst = np.log(np.asarray(bands_hz, dtype=np.float64))

        def resample(values: tuple[float, ...]) -> tuple[float, ...]:
            return tuple(float(v) for v in np.interp(dst, src, np.asarray(values, float)))

        return Material(self.name, tuple(float(b) for b in bands_hz),
                        resample(self.absorption), resample(self.scattering),
                        resample(self.transmission), self.description, self.source)


@dataclass(frozen=True)
class MaterialLibrary:
    """Named materials and the rule that gives a semantic label its material."""

    name: str
    materials: Mapping[str, Material]
    label_rule: str  # "table" (a label -> material map) or "substring" (SonicSet's rule)
    label_table: Mapping[str, str] = field(default_factory=dict)
    default_material: str = ""
    substring_labels: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def names(self) -> tuple[str, ...]:
        return tuple(self.materials)

    def get(self, name: str) -> Material:
        try:
            return self.materials[name]
        except KeyError:
            raise GeometryError(f"material: expected a name in library {self.name!r}, got "
                                f"{name!r}" + _hint(name, list(self.materials))) from None

    def with_scattering(self, scattering: Sequence[float],
                        bands_hz: Sequence[float] = OCTAVE_BANDS_HZ) -> MaterialLibrary:
        """This library with every material's scattering coefficients replaced by
        ``scattering`` (on ``bands_hz``, carried onto each material's own bands by
        log-frequency interpolation, end values held); absorption and transmission kept.

        ``1.0`` everywhere makes every reflection fully diffuse (Lambert): what RLR, the
        engine SonicSet was rendered with, computes whatever its material table says
        (``bench/bench_sonicset_scattering.py``)."""
        values = np.asarray(scattering, dtype=np.float64).reshape(-1)
        src = np.log(np.asarray(bands_hz, dtype=np.float64))
        if len(values) != len(src) or not np.all((values >= 0.0) & (values <= 1.0)):
            raise GeometryError(f"scattering: expected {len(src)} values in [0, 1], one per "
                                f"band {list(bands_hz)}, got {values.tolist()}")
        replaced = {}
        for name, m in self.materials.items():
            on = np.interp(np.log(np.asarray(m.bands_hz, dtype=np.float64)), src, values)
            replaced[name] = dataclasses.replace(m, scattering=tuple(float(v) for v in on))
        return MaterialLibrary(self.name, replaced, self.label_rule, self.label_table,
                               self.default_material, self.substring_labels)

    def with_materials(self, custom: Mapping[str, Material]) -> MaterialLibrary:
        """This library plus (or overridden by) user materials."""
        merged = dict(self.materials)
        merged.update(custom)
        return MaterialLibrary(self.name, merged, self.label_rule, self.label_table,
                               self.default_material, self.substring_labels)

    def material_for_label(self, label: str) -> str:
        """The material a face with semantic ``label`` (e.g. an mpcat40 category) gets."""
        if self.label_rule == "substring":
            category = str(label).lower()
            best, best_count = self.default_material, 0
            for name, labels in self.substring_labels:
                count = sum(1 for x in labels if x.lower() in category)
                if count > best_count:
                    best, best_count = name, count
            return best
        return self.label_table.get(str(label), self.default_material)

    def maps_label(self, label: str) -> bool:
        """Whether the library's rule gives ``label`` a material of its own (False: the label
        gets the library's default material because nothing matched it)."""
        if self.label_rule == "substring":
            category = str(label).lower()
            return any(x.lower() in category for _, labels in self.substring_labels
                       for x in labels)
        return str(label) in self.label_table

    def coefficients(self, names: Sequence[str], bands_hz: Sequence[float]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Absorption, scattering and transmission, each ``(len(names), len(bands_hz))``."""
        rows = [self.get(n).at_bands(bands_hz) for n in names]
        shape = (len(rows), len(bands_hz))

        def stack(kind: str) -> np.ndarray:
            if not rows:
                return np.zeros(shape)
            return np.array([getattr(r, kind) for r in rows], dtype=np.float64)

        return stack("absorption"), stack("scattering"), stack("transmission")


def _data(name: str) -> Any:
    text = resources.files("sonicspec").joinpath("data", "materials", name).read_text("utf-8")
    return json.loads(text)


def _pairs(flat: Sequence[float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return tuple(float(x) for x in flat[0::2]), tuple(float(x) for x in flat[1::2])


def _sonicset() -> MaterialLibrary:
    materials: dict[str, Material] = {}
    labels = []
    for entry in _data("mp3d_material_config.json")["materials"]:
        freqs, absorption = _pairs(entry["absorption"])
        s_freqs, scattering = _pairs(entry["scattering"])
        t_freqs, transmission = _pairs(entry["transmission"])
        # The table gives each coefficient on its own frequencies; resample the others onto
        # the absorption frequencies so one Material holds all three (they agree in the table).
        base = Material(entry["name"], freqs, absorption,
                        Material("s", s_freqs, scattering, scattering, scattering)
                        .at_bands(freqs).absorption,
                        Material("t", t_freqs, transmission, transmission, transmission)
                        .at_bands(freqs).absorption,
                        source="SonicSet / SoundSpaces 2.0 mp3d_material_config.json (CC BY)")
        materials[entry["name"]] = base
        labels.append((entry["name"], tuple(entry.get("labels", []))))
    return MaterialLibrary("sonicset", materials, "substring", {}, SONICSET_DEFAULT,
                           tuple(labels))


def _sonicspec() -> MaterialLibrary:
    doc = _data("sonicspec.json")
    bands = tuple(float(b) for b in doc["bands_hz"])
    classes = doc["scattering_classes"]
    materials = {}
    for entry in doc["materials"]:
        scattering = entry["scattering"]
        if isinstance(scattering, str):
            scattering = classes[scattering]["values"]
        if "transmission" in entry:
            transmission = tuple(entry["transmission"])
        else:
            transmission = mass_law_transmission(bands, entry["surface_density_kg_m2"])
        materials[entry["name"]] = Material(
            entry["name"], bands, tuple(entry["absorption"]), tuple(scattering), transmission,
            entry["description"], entry["absorption_source"])
    table = _data("mpcat40_to_sonicspec.json")
    return MaterialLibrary("sonicspec", materials, "table", table["map"], table["default"])


@cache
def load_library(name: str) -> MaterialLibrary:
    """A built-in library by name (cached)."""
    if name == "sonicspec":
        return _sonicspec()
    if name == "sonicset":
        return _sonicset()
    raise GeometryError(f"material library: expected one of {', '.join(LIBRARY_NAMES)}, got "
                        f"{name!r}" + _hint(name, LIBRARY_NAMES))


def material_library(name: str = "sonicspec",
                     custom: Mapping[str, Mapping[str, Any]] | None = None,
                     scattering: Sequence[float] | None = None) -> MaterialLibrary:
    """A built-in library with user materials added (a name equal to a library material
    replaces it).

    Parameters
    ----------
    name : {"sonicspec", "sonicset"}
        The built-in library.
    custom : mapping, optional
        Name -> ``{"absorption": [...], "scattering": [...], "transmission": [...],
        "description": "..."}``, seven values per coefficient on the octave bands
        125 Hz–8 kHz (the spec's ``materials.custom``, dumped).
    scattering : sequence of float, optional
        Seven values on the octave bands 125 Hz–8 kHz that replace every material's
        scattering, custom ones included (the spec's ``materials.scattering_override``;
        :meth:`MaterialLibrary.with_scattering`). None: each material's own.

    Raises
    ------
    GeometryError
        An unknown library, or a custom material with the wrong number of values or values
        outside [0, 1].
    """
    library = load_library(name)
    if custom:
        library = library.with_materials({
            key: custom_material(key, m["absorption"], m["scattering"], m["transmission"],
                                 OCTAVE_BANDS_HZ, m.get("description", ""))
            for key, m in custom.items()
        })
    return library if scattering is None else library.with_scattering(scattering)


def assign_materials(mesh: SceneMesh, library: MaterialLibrary,
                     label_materials: Mapping[str, str] | None = None,
                     default: str | None = None, *, where: str = "materials") -> SceneMesh:
    """Materials of a mesh's faces from their labels.

    A label takes the material ``label_materials`` maps it to, else the library's label rule
    (SonicSet's substring rule, or sonicspec's mpcat40 table); faces without a label take
    ``default`` when given. Anything else falls back to the library's default material, and
    says so.

    Parameters
    ----------
    mesh : SceneMesh
        The mesh, labelled or not (:func:`sonicspec.geometry.io.load_mesh` labels faces by
        object or group name, or by a PLY face property).
    library : MaterialLibrary
        Whose label rule and default apply.
    label_materials : mapping, optional
        Label -> material name, before the library's rule.
    default : str, optional
        Material of faces without a label.
    where : str
        What the warning names (a scene id, a file).

    Returns
    -------
    SceneMesh
        The mesh with ``materials`` and ``face_material`` set; names are not checked against
        the library here (:meth:`MaterialLibrary.coefficients` does).

    Warns
    -----
    SonicspecWarning
        Faces fell back to the library's default material: the labels (or "faces without a
        label"), each with its share of the surface area and the material it got. An OBJ
        whose objects lost their names, or labels the library does not know, would otherwise
        give every such face one material in silence (4 s of T30 in a room that has 0.6 s).
    """
    overrides = dict(label_materials or {})
    fell_back: dict[str, str] = {}  # label (or UNLABELED) -> the material it fell back to

    def rule(label: str) -> str:
        if label in overrides:
            return overrides[label]
        if label == UNLABELED and default is not None:
            return default
        material = library.material_for_label(label)
        if label == UNLABELED or not library.maps_label(label):
            fell_back[label] = material
        return material

    if mesh.face_label is None:
        if default:
            return mesh.with_materials(default)
        fell_back[UNLABELED] = library.material_for_label(UNLABELED)
        assigned = mesh.with_materials(fell_back[UNLABELED])
    else:
        assigned = mesh.with_materials(rule)
    if fell_back:
        _warn_fallback(assigned, fell_back, library, where)
    return assigned


def _warn_fallback(mesh: SceneMesh, fell_back: dict[str, str], library: MaterialLibrary,
                   where: str) -> None:
    areas = mesh.face_areas
    total = float(areas.sum()) or 1.0
    items = []
    for label, material in fell_back.items():
        if mesh.face_label is None:
            share = 1.0
        else:
            share = float(areas[mesh.face_label == mesh.labels.index(label)].sum()) / total
        name = "faces without a label" if label == UNLABELED else repr(label)
        items.append((share, f"{name} ({100 * share:.1f} % of the area -> {material})"))
    items.sort(key=lambda item: -item[0])
    share = sum(s for s, _ in items)
    warnings.warn(
        f"{where}: expected a material for every face label, got none for "
        f"{', '.join(text for _, text in items)}; the fallback of library {library.name!r} "
        f"covers {100 * share:.1f} % of the area in all; map each label to a material "
        "(a default material covers faces without a label)",
        SonicspecWarning, stacklevel=3)


def material_names(library: str) -> tuple[str, ...]:
    """Names in a built-in library (used by spec validation)."""
    return load_library(library).names()


def custom_material(name: str, absorption: Sequence[float], scattering: Sequence[float],
                    transmission: Sequence[float], bands_hz: Sequence[float],
                    description: str = "") -> Material:
    """A user-defined material (from the spec's ``materials.custom``)."""
    return Material(name, tuple(float(b) for b in bands_hz), tuple(absorption),
                    tuple(scattering), tuple(transmission), description, "user-defined")
