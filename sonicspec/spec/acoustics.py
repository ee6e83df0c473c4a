"""Acoustic simulation settings for the Embree tracer."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel

OctaveBand = Literal[125, 250, 500, 1000, 2000, 4000, 8000]


class AcousticsSpec(SpecModel):
    """Tracer settings: image sources for the early part, stochastic rays for the late part."""

    rays: int = Field(
        20_000,
        ge=100,
        le=1_000_000,
        description="Rays launched per source for the late part (splitting adds children); at "
        "most 1,000,000. Rays are traced in batches of 8,192, so memory does not grow with the "
        "count but time does: 1,000,000 rays take about 14 s per source in a 6 m room on one "
        "core, and converged references use 50,000.",
    )
    image_source_order: int = Field(
        3, ge=0, le=8, description="Highest reflection order found exactly by image sources."
    )
    max_rir_length_s: Annotated[float, Field(gt=0, le=20.0)] | Literal["auto"] = Field(
        "auto",
        description="Longest RIR, seconds, or 'auto'. Either way a RIR ends where every "
        "band's late decay (its Schroeder curve) is 60 dB below its early level; 'auto' "
        "traces rays up to max_rir_cap_s, a number up to that many seconds (at most 20). "
        "Where the rays run out before 60 dB (Russian roulette, few rays) the late envelope "
        "goes on with the decay fitted to its last 20 dB. Where max_rir_cap_s cuts a "
        "decay short a warning names the scene and the band; a number is taken as asked "
        "(the facts report the cut). The RIR facts (sonicspec rir "
        "--json, RirResult.tail, the dataset metadata) give the length and how it was "
        "chosen.",
    )
    max_rir_cap_s: float = Field(
        10.0,
        gt=0,
        le=60.0,
        description="Longest RIR with max_rir_length_s: auto, seconds (at most 60). The "
        "tracer follows rays this long and keeps a histogram this long per trajectory point "
        "(8 bytes per band and histogram bin), so the cap bounds time and memory; a live room "
        "whose decay needs longer is cut here with a warning naming the scene and the band. "
        "10 s holds a hall with a 9 s reverberation time.",
    )
    energy_threshold_db: float = Field(
        80.0,
        gt=0,
        le=200.0,
        description="Decay below the direct sound at which a ray is terminated, dB.",
    )
    bands_hz: list[OctaveBand] | Literal["auto"] = Field(
        "auto",
        description="Octave bands simulated; 'auto' is every band from 125 Hz whose upper edge "
        "lies below Nyquist.",
    )
    air_absorption: bool = Field(True, description="Apply ISO 9613-1 air absorption.")
    temperature_c: float = Field(20.0, ge=-20, le=50, description="Air temperature, °C.")
    relative_humidity_pct: float = Field(
        50.0, ge=0, le=100, description="Relative humidity of the air, percent."
    )
    transmission: bool = Field(
        True, description="Let sound pass through surfaces by their transmission coefficient."
    )
    diffraction: bool = Field(
        True,
        description="Add edge-diffracted sound (UTD, first and second order, and one edge "
        "with one reflection) round the diffracting edges of the traced mesh: the sound of a "
        "source out of sight, and the wave that keeps the level continuous at every shadow "
        "boundary. Costs about +20 % per RIR in a furnished apartment.",
    )
    diffraction_max_edges: int = Field(
        256,
        ge=0,
        le=100_000,
        description="Edge budget of diffraction: at most this many diffracting edges, the "
        "longest, are used (a scan can have thousands of creases).",
    )
    detection: Literal["diffuse_rain", "receiver_volume"] = Field(
        "diffuse_rain",
        description="How rays reach the receiver: a shadow ray from every hit (low variance) "
        "or by crossing a sphere.",
    )
    receiver_radius_m: float = Field(
        0.1, gt=0, le=2.0, description="Radius of the detection sphere around a receiver, metres."
    )
    free_air_ball_m: float = Field(
        0.0,
        ge=0,
        le=5.0,
        description="Radius, metres, to which the late specular-detection ball may grow "
        "past nearby surfaces; beyond them it counts only the air the receiver sees (a "
        "visibility map per receiver gives the test and the volume). 0: the ball stops at the "
        "receiver's clearance and at 1 m. In scans whose ceiling caps the ball near 1 m, 4 "
        "(with ray_splitting) lowers the seed-to-seed T30 spread about 2x; the late energy is "
        "then averaged over that much of the receiver's visible air. Each crossing costs per "
        "receiver: with many trajectory points in a small room it can cost 4x the trace.",
    )
    ray_splitting: float = Field(
        0.0,
        ge=0,
        le=100.0,
        description="Specular splitting rate r: a ray never scattered goes on specularly and "
        "sends its scattered share as a child ray with probability min(1, r x its energy / "
        "launch energy). 0: off (one continuing ray per hit). Unbiased either way; in scans "
        "with little scattering (s about 0.1) the late decay rides on a few long specular "
        "chains, and r = 2 with free_air_ball_m 4 cuts the seed-to-seed T30 spread several "
        "times at equal CPU (see specs/sonicset.yaml); in diffuse rooms it gains nothing, and "
        "in live rooms (low absorption) it is costly: a ray keeps its energy, so it spawns "
        "children at many bounces.",
    )
    roulette_db: float = Field(
        30.0,
        ge=0,
        le=200.0,
        description="Russian roulette of weak rays, dB below their launch energy: a ray that "
        "falls this far goes on with probability E/E_r, its energy raised to E_r (unbiased). "
        "0: off (rays are followed to energy_threshold_db). Below energy_threshold_db it also "
        "keeps the tail past that threshold. The default 30 halves the tracer's CPU time in "
        "absorbing rooms for about the same seed-to-seed spread.",
    )
    horizontal_guiding: float = Field(
        0.3,
        ge=0,
        lt=1.0,
        description="Share of launched directions (and of each path's first diffuse "
        "reflection and of the splitting's children) sent to thin horizontal bands (|sin "
        "elevation| < 0.005, 0.02 and 0.08, z up), weighted by the ratio of plain to mixed "
        "density (unbiased). 0: off. Above 0.5 too few plain directions remain. Where "
        "floor and ceiling absorb more than the walls (furnished scans: carpet, acoustic "
        "tile) the late tail rides on near-horizontal rays, a sliver of the sphere plain "
        "sampling reaches with few rays: 0.3 cuts the T30 error of a 20,000-ray trace in "
        "such a scan about 3x at the same CPU; in diffuse rooms it raises the (already "
        "small) seed-to-seed spread about 1.5x.",
    )
    simplify_tolerance_m: float = Field(
        0.001,
        ge=0,
        le=0.1,
        description="Before tracing, flat areas of the mesh are re-triangulated with fewer, "
        "larger triangles (half-edge collapses that keep creases and material boundaries "
        "where they are); no surface moves by more than this, metres. 0: trace the mesh as "
        "given. The tracer's cost per hit grows with the triangle count: a procedural "
        "apartment cut into 107,000 coplanar triangles goes back to 972 and its RIRs take "
        "1.5x less CPU. The default merges what is flat to a millimetre; on scans, raise it "
        "towards the scan's noise (a mesh with 2 mm noise loses two thirds of its triangles "
        "at 0.02 m, a quarter of the 8.6 cm wavelength at 4 kHz; validate warns above it).",
    )
    mirror_tolerance_m: float = Field(
        0.0001,
        ge=0.0001,
        le=0.05,
        description="Image-source mirrors: edge-connected triangles of one material whose "
        "vertices lie within this distance of a common plane (their normals within 0.5 rad "
        "of it) reflect as one flat mirror, on the plane fitted to them, metres. The default "
        "merges only exactly flat surfaces (procedural rooms, CAD). A scan's walls are never "
        "flat to a tenth of a millimetre: with 2 mm vertex noise every triangle stays a mirror "
        "of its own and the image-source search needs hundreds of times more candidates; "
        "0.01 merges them (the sonicset presets use it), an error of the order of that noise "
        "in each reflection's delay.",
    )
    histogram_bin_s: float = Field(
        0.001, gt=0, le=0.05, description="Width of the energy-time histogram bins, seconds."
    )
