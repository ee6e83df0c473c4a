"""Edge diffraction in the RIR engine (issue 19): a screen room and a door room built here,
measured against the exact wedge; a source walking out of sight fades without a step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics import engine
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.acoustics.theory import Wedge, edge_path_length_m, wedge_diffraction_ir
from sonicspec.testing.meshes import voxel_air_surface
from sonicspec.testing.rooms import shoebox

FS = 16000
C = 343.0
BANDS = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0)
CHECKED = slice(1, 6)  # 250–4000 Hz


def settings(diffraction: bool = True, order: int = 1) -> engine.SimulationSettings:
    return engine.SimulationSettings(
        rays=100, sample_rate_hz=FS, bands_hz=BANDS, image_source_order=order,
        max_rir_length_s=0.2, energy_threshold_db=60.0, air_absorption=False,
        temperature_c=20.0, relative_humidity_pct=50.0, transmission=False, diffuse_rain=True,
        receiver_radius_m=0.1, histogram_bin_s=0.001, speed_of_sound_m_s=C,
        diffraction=diffraction)  # fmt: skip


def rigid(vertices: np.ndarray, faces: np.ndarray, alpha: float = 0.05) -> AcousticScene:
    n, b = len(faces), len(BANDS)
    return AcousticScene(vertices, faces, np.full((n, b), alpha), np.zeros((n, b)),
                         np.zeros((n, b)))


def screen_room() -> AcousticScene:
    """An 8 × 4 × 3 m room cut at x = 4 by a one-sided sheet 1.8 m high, wall to wall."""
    v, f = shoebox(8.0, 4.0, 3.0)
    sheet_v = np.array([[4.0, 0.0, 0.0], [4.0, 4.0, 0.0], [4.0, 4.0, 1.8], [4.0, 0.0, 1.8]])
    sheet_f = np.array([[0, 1, 2], [0, 2, 3]]) + len(v)
    return rigid(np.vstack([v, sheet_v]), np.vstack([f, sheet_f]))


def thin_door_room() -> AcousticScene:
    """A 6 × 3 × 2.5 m room cut at x = 3 by a one-sided partition with a 0.9 × 2.1 m door
    (y 1 → 1.9): two rooms joined by a door in a thin wall."""
    v, f = shoebox(6.0, 3.0, 2.5)
    ys, zs = [0.0, 1.0, 1.9, 3.0], [0.0, 2.1, 2.5]
    grid = np.array([[3.0, y, z] for y in ys for z in zs])
    tris = []
    for i in range(3):
        for k in range(2):
            if (i, k) == (1, 0):
                continue  # the door
            a, b = i * 3 + k, (i + 1) * 3 + k
            tris += [[a, b, b + 1], [a, b + 1, a + 1]]
    return rigid(np.vstack([v, grid]), np.vstack([f, np.array(tris) + len(v)]))


def door_room() -> AcousticScene:
    """Two 3 × 3 × 2.5 m rooms joined by a 0.9 × 2.1 m door in a 0.2 m wall (x 3 → 3.2)."""
    xs = np.array([0.0, 3.0, 3.2, 6.2])
    ys = np.array([0.0, 1.0, 1.9, 3.0])
    zs = np.array([0.0, 2.1, 2.5])
    air = np.ones((3, 3, 2), bool)
    air[1] = False
    air[1, 1, 0] = True
    mesh = voxel_air_surface(xs, ys, zs, air)
    return rigid(mesh.vertices, mesh.faces)


def rirs(scene, mic, sources, diffraction=True, order=1):
    return engine.simulate_rirs(scene, np.asarray(mic, float), np.asarray(sources, float),
                                settings(diffraction, order), np.random.default_rng(0))


def band_energy(x: np.ndarray, fs: float, start_s: float, stop_s: float) -> np.ndarray:
    """Mean ``|H(f)|²`` per octave band (edges f/√2 … f√2) of the impulse response samples of
    ``x`` in [start, stop): a transfer-function level, the same at any sample rate."""
    seg = x[round(start_s * fs):round(stop_s * fs)]
    n = 1 << 14
    spec = np.abs(np.fft.rfft(seg, n)) ** 2
    f = np.fft.rfftfreq(n, 1 / fs)
    return np.array([spec[(f >= b / 2**0.5) & (f < b * 2**0.5)].mean() for b in BANDS])


def compare_first_arrival(scene, wedge: Wedge, src, mic, window_s: float) -> None:
    (rir,), (facts,) = rirs(scene, mic, [src])
    assert facts.direct == "diffracted"
    length = edge_path_length_m(wedge, src, mic)
    onset = length / C
    h = rir[0].astype(np.float64)
    first = int(np.flatnonzero(np.abs(h) > 0.05 * np.abs(h).max())[0])
    peak = first + int(np.argmax(np.abs(h[first:first + 8])))
    assert abs(peak - onset * FS) <= 1.0
    # nothing earlier (beyond the band filters' low-frequency skirts)
    assert np.abs(h[: int(onset * FS) - 40]).max() < 0.01 * np.abs(h).max()
    fs_ref = 4 * FS
    exact = wedge_diffraction_ir(wedge, src, mic, fs_ref, int((onset + 0.05) * fs_ref), C)
    lo, hi = onset - 0.002, onset + window_s
    err = 10 * np.log10(band_energy(h, FS, lo, hi) / band_energy(exact, fs_ref, lo, hi))
    assert np.all(np.abs(err[CHECKED]) < 3.0), err


def test_screen_room_first_arrival_over_the_top_edge() -> None:
    top = Wedge.half_plane([4.0, 0.0, 1.8], [0, 1, 0], [0, 0, -1])
    # (not symmetric: the floor reflection would meet the floor exactly at the sheet's foot)
    compare_first_arrival(screen_room(), top, np.array([2.5, 2.0, 1.0]),
                          np.array([6.0, 2.0, 1.2]), 0.0025)


def test_door_room_first_arrival_round_the_jamb() -> None:
    jamb = Wedge.half_plane([3.0, 1.0, 0.0], [0, 0, 1], [0, -1, 0])
    src, mic = np.array([1.5, 2.5, 1.2]), np.array([3.4, 0.5, 1.2])
    compare_first_arrival(thin_door_room(), jamb, src, mic, 0.002)


def test_door_room_second_order_round_both_jamb_edges() -> None:
    src, mic = np.array([1.5, 0.4, 1.2]), np.array([3.8, 0.3, 1.2])
    (rir,), (facts,) = rirs(door_room(), mic, [src])
    assert facts.direct == "diffracted"
    run = math.dist(src[:2], [3.0, 1.0]) + 0.2 + math.dist([3.2, 1.0], mic[:2])
    h = np.abs(rir[0])
    first = int(np.flatnonzero(h > 0.05 * h.max())[0])
    peak = first + int(np.argmax(h[first:first + 8]))
    assert abs(peak - run / C * FS) <= 1.0
    (_,), (off,) = rirs(door_room(), mic, [src], diffraction=False)
    assert off.direct == "blocked" and off.diffracted_paths == 0 and off.diffraction_edges is None


def test_a_thin_thick_screen_heard_over_both_edges_is_the_half_plane() -> None:
    """Two edges: a screen 2 cm thick (two right-angled edges 2 cm apart) is heard over both
    (second order); as the thickness goes to zero the exact field is the half-plane's, so
    the two-edge path's first arrival must match the exact half-plane (Biot–Tolstoy–Medwin)
    within the issue's 3 dB in every octave 250–4000 Hz (measured: 2.3–2.6 dB high)."""
    w = 0.02
    xs, ys, zs = np.array([0.0, 4.0 - w / 2, 4.0 + w / 2, 8.0]), np.array([0.0, 4.0]), \
        np.array([0.0, 1.8, 3.0])
    air = np.ones((3, 1, 2), bool)
    air[1, 0, 0] = False
    mesh = voxel_air_surface(xs, ys, zs, air)
    scene = rigid(mesh.vertices, mesh.faces)
    src, mic = np.array([2.5, 2.0, 1.0]), np.array([6.0, 2.0, 1.2])
    (rir,), (facts,) = rirs(scene, mic, [src])
    assert facts.direct == "diffracted"
    top = Wedge.half_plane([4.0, 0.0, 1.8], [0, 1, 0], [0, 0, -1])
    onset = (edge_path_length_m(top, src, mic) + w) / C  # over the two edges
    fs_ref = 4 * FS
    exact = wedge_diffraction_ir(top, src, mic, fs_ref, int((onset + 0.05) * fs_ref), C)
    ours = band_energy(rir[0].astype(np.float64), FS, onset - 0.002, onset + 0.0025)
    shift = w / C  # the half-plane's path is w shorter
    err = 10 * np.log10(ours / band_energy(exact, fs_ref, onset - 0.002 - shift,
                                           onset + 0.0025 - shift))
    assert np.all(np.abs(err[CHECKED]) < 3.0), err


def walk_levels(scene, mic, points, diffraction=True) -> np.ndarray:
    """Level (dB) of each position's early sound: the first 5 ms after the earliest path
    (-300 dB for silence: with causal band shaping nothing of a later path reaches back into
    a blocked position's window)."""
    out, facts = rirs(scene, mic, points, diffraction)
    start = min(np.linalg.norm(points - mic, axis=1)) / C
    return np.array([10 * np.log10(1e-30 + np.sum(r[0, int(start * FS) - 40:
                                                 int((start + 0.008) * FS)].astype(float) ** 2))
                     for r in out]), [f.direct for f in facts]


@pytest.mark.parametrize("y_cross", [2.0, 1.0], ids=["direct-to-edge", "edge-to-two-edges"])
def test_a_source_walking_out_of_sight_round_the_door_fades_smoothly(y_cross: float) -> None:
    # A walk at 1.5 m/s along x = 2 in room A; the receiver in room B sees it until y = 2.0
    # (then round the room-B jamb edge), and that edge until y = 1.0 (then round both).
    step = 1.5e-3  # 1 ms of walking
    ys = y_cross + step * (np.arange(-20, 20) + 0.5)
    points = np.column_stack([np.full_like(ys, 2.0), ys, np.full_like(ys, 1.2)])[::-1]
    mic = np.array([3.8, 0.5, 1.2])
    levels, paths = walk_levels(door_room(), mic, points)
    assert len(set(paths)) == 2 if y_cross == 2.0 else set(paths) == {"diffracted"}
    assert np.abs(np.diff(levels)).max() < 3.0
    if y_cross == 2.0:  # without diffraction the same walk steps by far more
        off, _ = walk_levels(door_room(), mic, points, diffraction=False)
        assert np.abs(np.diff(off)).max() > 10.0


def test_edges_are_found_once_per_scene_and_budgeted() -> None:
    scene = door_room()
    edges = engine.scene_edges(scene, 4)
    assert edges is engine.scene_edges(scene, 4)
    assert len(edges) == 4 and edges.n_found == 6


def test_diffracted_paths_carry_direction_materials_and_air() -> None:
    from sonicspec.acoustics.paths.edge_paths import diffracted_sound

    src, mic = np.array([[2.5, 2.0, 1.0]]), np.array([6.0, 2.0, 1.2])
    scene = screen_room()
    edges = engine.scene_edges(scene, 256)

    def first(scene, air=None):
        (a,) = diffracted_sound(scene, edges, src, mic, BANDS, air, C, second_order=False,
                                reflections=False)
        k = int(np.argmin(a.times_s))
        return a.amplitudes[k], a.directions[k], a.path_length_m[k]

    amp, direction, length = first(scene)
    # over the top edge: the apex divides the path as the distances to the edge
    apex = np.array([4.0, 2.0, 1.8])
    np.testing.assert_allclose(direction, (apex - mic) / np.linalg.norm(apex - mic), atol=1e-9)
    assert length == pytest.approx(np.linalg.norm(apex - src[0]) + np.linalg.norm(mic - apex))
    air = np.linspace(0.001, 0.05, len(BANDS))
    np.testing.assert_allclose(first(scene, air)[0], amp * np.exp(-0.5 * air * length))
    # absorbing faces weaken the wave their reflection would have completed, not the rest
    n, b = scene.n_faces, len(BANDS)
    soft = AcousticScene(scene.vertices, scene.faces, np.full((n, b), 0.9), np.zeros((n, b)),
                         np.zeros((n, b)))
    soft_amp = first(soft)[0]
    assert np.all(np.abs(soft_amp) < np.abs(amp)) and np.all(np.abs(soft_amp) > 0.3 * np.abs(amp))
