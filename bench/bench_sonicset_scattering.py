"""The ``sonicset`` preset's reverberation against RLR's, with its scattering as RLR applies it
and with the table's measured scattering (issue 30).

RLR (``rlr-audio-propagation``, the engine SonicSim drives and SonicSet was rendered with)
ignores the material table's scattering: every reflection is diffuse. sonicspec honours it, so
with SonicSet's table (scattering 0.10-0.15 on walls, carpet and furniture) its late decay in
a furnished room is longer. The ``sonicset`` preset therefore sets
``materials.scattering_override: 1.0`` (every surface fully diffuse, absorption kept); a
realistic preset leaves it null. This bench shows both against RLR.

``rlr-audio-propagation`` is a benchmark-only optional dependency with a non-commercial licence
(CC BY-NC 4.0), never imported by the package:  pip install rlr-audio-propagation
Without it this script prints a message and exits 0.

Reproduce:  python bench/bench_sonicset_scattering.py           (about 3 minutes on 1 core)
            python bench/bench_sonicset_scattering.py --quick   (2 seeds, 2 RLR draws)

What it does
* Scene, source and microphone of ``bench_rlr.py``: the furnished six-room apartment (about
  100 k triangles, SonicSet's materials by label), one source and one microphone 5.8 m apart
  in the same room with line of sight.
* RLR at SonicSim's settings (16 kHz, 50,000 indirect rays, SH orders 5/3), with SonicSet's
  table as it is, at the bench position and ``--draws``-1 positions 5 cm away (RLR is
  deterministic per position; the draws give its own Monte-Carlo spread); once with every
  scattering coefficient of the table set to 1 (RLR's answer does not move: it ignores them).
* sonicspec with the ``sonicset`` preset's ``acoustics`` and ``materials`` sections as
  shipped (``scattering_override: 1.0``), and the same with ``scattering_override: null``
  (the table's measured scattering), ``--seeds`` seeds each, through the same library call
  the rir step makes (``material_library`` with the override, ``acoustic_scene``,
  ``simulate_rirs``).
* T30, EDT and C50 per octave band (125 Hz-4 kHz, the bands SonicSet's table covers) of each
  RIR by sonicspec's ISO 3382-1 routine: the mean and standard deviation over seeds (over
  positions for RLR) and, for sonicspec, the ratio (T30, EDT) or difference (C50) to RLR's
  mean. CPU per RIR after a 10-ray warm-up RIR (compiled kernels, tracer tables).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import resource
import sys
import tempfile
import time
import warnings
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_rlr import (
    BANDS_HZ,
    MIC_M,
    SAMPLE_RATE_HZ,
    apartment_mesh,
    check_positions,
    diffuse_material_json,
    figures,
    rlr_config,
    rlr_material_json,
    rlr_rir,
    rlr_source,
)

from sonicspec.acoustics.engine import SimulationSettings, acoustic_scene, simulate_rirs
from sonicspec.acoustics.paths.image_sources import planar_regions
from sonicspec.geometry.materials import material_library
from sonicspec.spec.acoustics import AcousticsSpec
from sonicspec.spec.materials import MaterialsSpec
from sonicspec.units import SPEED_OF_SOUND_M_S

KEYS = (("t30_s", "T30 (s)", ".2f"), ("edt_s", "EDT (s)", ".2f"), ("c50_db", "C50 (dB)", ".1f"))


def preset_sections() -> tuple[AcousticsSpec, MaterialsSpec]:
    """The ``sonicset`` preset's ``acoustics`` and ``materials`` sections, as shipped."""
    text = resources.files("sonicspec.spec").joinpath("templates/sonicset.yaml").read_text()
    doc = yaml.safe_load(text)
    return AcousticsSpec(**doc["acoustics"]), MaterialsSpec(**doc["materials"])


def mean_figures(runs: list[dict]) -> dict:
    """Per figure, the mean over runs per band and broadband (NaN where a fit failed)."""
    out: dict = {"runs": len(runs)}
    for key, _, _ in KEYS:
        per_band = np.array([[np.nan if v is None else v for v in r[key]] for r in runs], float)
        broad = np.array([np.nan if r["broadband"][key] is None else r["broadband"][key]
                          for r in runs], float)
        out[key] = np.nanmean(per_band, axis=0).tolist()
        out[f"{key}_spread"] = np.nanstd(per_band, axis=0).tolist()
        out[f"{key}_broadband"] = float(np.nanmean(broad))
    return out


def sonicspec_runs(mesh, acoustics: AcousticsSpec, materials: MaterialsSpec,
                   seeds: list[int]) -> tuple[list[dict], float]:
    settings = SimulationSettings.from_spec(acoustics.model_dump(mode="json"), SAMPLE_RATE_HZ,
                                            SPEED_OF_SOUND_M_S)
    library = material_library(materials.library, {}, materials.scattering_override)
    scene = acoustic_scene(mesh, library, settings)
    regions = planar_regions(scene)
    source = rlr_source(0)
    check_positions(scene, source, MIC_M)
    # compiled kernels loaded and the tracer's tables built before the clock starts (as the
    # rir step's first RIR of a job pays them once): a 10-ray RIR
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate_rirs(scene, MIC_M, source[None], dataclasses.replace(settings, rays=10),
                      np.random.default_rng(0), regions=regions)
    runs, c0 = [], time.process_time()
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # order 3 stops at 2 here (its own warning)
            (rir,), _ = simulate_rirs(scene, MIC_M, source[None], settings,
                                      np.random.default_rng(seed), regions=regions)
        runs.append(figures(rir[0], SAMPLE_RATE_HZ))
    return runs, (time.process_time() - c0) / len(seeds)


def rlr_runs(mesh, tmp: Path, draws: int, diffuse: bool) -> list[dict]:
    import rlr_audio_propagation as rlr  # benchmark-only optional dependency

    table = tmp / "rlr_materials.json"
    rlr_material_json(mesh, table)
    if diffuse:
        diffuse_material_json(table, tmp / "rlr_materials_diffuse.json")
        table = tmp / "rlr_materials_diffuse.json"
    cfg = rlr_config("sonicsim", rlr)
    return [figures(rlr_rir(rlr, cfg, mesh, table, rlr_source(d))[0], cfg.sample_rate)
            for d in range(draws)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=100_000)
    parser.add_argument("--seeds", type=int, default=8, help="sonicspec seeds per variant")
    parser.add_argument("--draws", type=int, default=4, help="RLR positions (5 cm apart)")
    parser.add_argument("--quick", action="store_true", help="2 seeds, 2 RLR draws")
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    if importlib.util.find_spec("rlr_audio_propagation") is None:
        print("bench_sonicset_scattering: rlr-audio-propagation is not installed "
              "(pip install rlr-audio-propagation); nothing to compare against")
        return 0
    seeds = list(range(2 if args.quick else args.seeds))
    draws = 2 if args.quick else args.draws
    w0 = time.perf_counter()
    mesh = apartment_mesh(args.triangles)
    acoustics, preset = preset_sections()
    measured = preset.model_copy(update={"scattering_override": None})
    rows: dict[str, dict] = {}
    cpu: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        c0 = time.process_time()
        rows["RLR, SonicSim's settings"] = mean_figures(rlr_runs(mesh, Path(tmp), draws, False))
        cpu["RLR"] = (time.process_time() - c0) / draws
        rows["RLR, every scattering 1"] = mean_figures(rlr_runs(mesh, Path(tmp), 1, True))
    for label, materials in (("sonicspec, sonicset preset (scattering_override 1.0)", preset),
                             ("sonicspec, measured scattering (override null)", measured)):
        runs, cpu[label] = sonicspec_runs(mesh, acoustics, materials, seeds)
        rows[label] = mean_figures(runs)
    wall = time.perf_counter() - w0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(f"# sonicset preset vs RLR: {mesh.n_faces:,} triangles, source-mic "
          f"{np.linalg.norm(rlr_source(0) - MIC_M):.2f} m; RLR {draws} positions, sonicspec "
          f"{len(seeds)} seeds per variant (the mean; ± the standard deviation over RLR's "
          "positions and sonicspec's seeds)")
    print(f"# preset acoustics: {acoustics.rays} rays, image sources to order "
          f"{acoustics.image_source_order}; preset materials: library {preset.library}, "
          f"scattering_override {preset.scattering_override}")
    ref = rows["RLR, SonicSim's settings"]
    head = " | ".join(f"{b:g}" for b in BANDS_HZ)
    for key, label, spec in KEYS:
        print(f"\n{label}, octave bands (Hz)\n\n| engine, setting | {head} | broadband |")
        print("|---" * (len(BANDS_HZ) + 2) + "|")
        for name, fig in rows.items():
            cells = []
            for k, v in enumerate(fig[key]):
                cell = format(v, spec)
                if fig["runs"] > 1:
                    cell += f" ± {fig[f'{key}_spread'][k]:{spec}}"
                cells.append(cell)
            print(f"| {name} | {' | '.join(cells)} | {fig[f'{key}_broadband']:{spec}} |")
        for name, fig in rows.items():
            if not name.startswith("sonicspec"):
                continue
            if key == "c50_db":
                diff = [a - b for a, b in zip(fig[key], ref[key], strict=True)]
                print(f"| {name} − RLR (dB) | " + " | ".join(f"{d:+.1f}" for d in diff)
                      + f" | {fig[f'{key}_broadband'] - ref[f'{key}_broadband']:+.1f} |")
            else:
                ratio = [a / b for a, b in zip(fig[key], ref[key], strict=True)]
                print(f"| {name} / RLR | " + " | ".join(f"{r:.2f}" for r in ratio)
                      + f" | {fig[f'{key}_broadband'] / ref[f'{key}_broadband']:.2f} |")
    print("\nCPU per RIR: " + ", ".join(f"{k} {v:.2f} s" for k, v in cpu.items()))
    print(f"wall {wall:.0f} s, CPU {usage.ru_utime + usage.ru_stime:.0f} s (getrusage)")
    print("reproduce: python bench/bench_sonicset_scattering.py"
          + (" --quick" if args.quick else ""))
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "cpu_per_rir_s": cpu}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
