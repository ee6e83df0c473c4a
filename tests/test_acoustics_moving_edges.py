"""Edge-diffracted paths of a moving source (issues 18 and 19): followed along the walk by
their edges, rendered as time-varying delays whose length is read between the RIR points, and
points added where a path appears, disappears or bends fast (``refined_early_paths``)."""

from __future__ import annotations

import numpy as np
from test_acoustics_diffraction_engine import FS, C, door_room, screen_room, settings

from sonicspec.acoustics import engine
from sonicspec.acoustics.bands import OctaveFilterBank
from sonicspec.acoustics.moving.delays import PathSet, _length_at, render_paths
from sonicspec.acoustics.theory import Wedge, edge_path_length_m
from sonicspec.audio.fidelity import dip_figures, snr_db, spectral_deviation_db
from sonicspec.geometry.navigation import resample_polyline

MIC = np.array([3.8, 0.5, 1.2])
ENDS = np.array([[2.0, 2.7, 1.2], [2.0, 0.4, 1.2]])  # out of sight round the door's jamb
SPEED = 1.5


def walk_render(spacing: float, refine: bool, dry: np.ndarray) -> tuple[np.ndarray, PathSet]:
    """The early paths of the walk through the door room (diffraction on, order 1), rendered
    from RIR points ``spacing`` apart, as the rir and render stages do."""
    scene, st = door_room(), settings(True, 1)
    points = resample_polyline(ENDS, spacing)
    _, facts = engine.simulate_rirs(scene, MIC, points, st, np.random.default_rng(0),
                                    keep_arrivals=True)
    heard = [f.early_arrivals for f in facts]
    if refine:
        fine = engine.refined_early_paths(scene, st, points, np.repeat(MIC[None], len(points), 0),
                                          heard, heard)
        paths = PathSet.identify(fine.sources_m, fine.from_mic).with_index(fine.at_index)
    else:
        paths = PathSet.identify(points, heard)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    index = np.interp(np.clip(np.arange(dry.size) / FS * SPEED, 0, along[-1]), along,
                      np.arange(len(points)))
    (y,) = render_paths(dry, index, points, paths, OctaveFilterBank(FS, st.bands_hz),
                        n_out=dry.size, speed_of_sound_m_s=C)
    return y, paths


def test_a_source_walking_out_of_sight_is_rendered_as_the_dense_walk() -> None:
    """The walk out of sight round the door jamb: its direct sound is cut by the jamb and
    taken over by the path round it, reflections come and go, 58 edge paths bend round the
    door. From RIR points 0.25 m apart with points added where the paths change, the early
    part matches the same renderer on points 5 mm apart (the converged walk); without the
    added points the paths fade over 0.25 m where the geometry switches them (13.7 dB)."""
    n = int(np.linalg.norm(ENDS[1] - ENDS[0]) / SPEED * FS) + FS // 4
    dry = np.random.default_rng(1).standard_normal(n)
    dense, dense_paths = walk_render(0.005, False, dry)
    coarse, paths = walk_render(0.25, True, dry)
    plain, _ = walk_render(0.25, False, dry)
    assert paths.diffracted.sum() == dense_paths.diffracted.sum() >= 50
    assert 11 < len(paths.at_index) < 461 // 2  # points added only where paths change
    core = slice(int(0.1 * FS), n - int(0.3 * FS))
    dev, _, _ = spectral_deviation_db(dense, coarse, FS, active=(core.start, core.stop))
    assert snr_db(dense[core], coarse[core]) >= 25, snr_db(dense[core], coarse[core])
    assert dip_figures(dev)["p5_db"] >= -0.5
    assert snr_db(dense[core], plain[core]) < 20

    def steps(y: np.ndarray) -> float:  # 10 ms levels every 1 ms of walk
        w = FS // 100
        e = np.convolve(y**2, np.ones(w) / w, mode="same")[core][:: FS // 1000]
        return float(np.abs(np.diff(10 * np.log10(e))).max())

    assert steps(coarse) < 3.0 and steps(coarse) < steps(dense) + 0.5


def test_a_diffracted_paths_length_is_read_exactly_between_points() -> None:
    """Over the screen's top edge (a half-plane at x = 4, edge at z = 1.8), a source walking
    behind it: the path's length read between RIR points 0.25 m apart (a cubic spline)
    against the exact shortest path over the edge at 300 places, within 0.02 mm (0.001 of
    a sample at 16 kHz; measured 4 µm)."""
    scene, st = screen_room(), settings(True, 1)
    mic = np.array([6.0, 2.0, 1.2])
    points = resample_polyline(np.array([[2.5, 0.6, 1.0], [2.0, 3.4, 1.4]]), 0.25)
    _, facts = engine.simulate_rirs(scene, mic, points, st, np.random.default_rng(0),
                                    keep_arrivals=True)
    paths = PathSet.identify(points, [f.early_arrivals for f in facts])
    first = np.flatnonzero(paths.diffracted & (paths.order == 1)
                           & np.all(~np.isnan(paths.lengths_m), axis=1))
    wedge = Wedge(point=np.array([4.0, 0.0, 1.8]), edge=np.array([0.0, 1.0, 0.0]),
                  face0=np.array([0.0, 0.0, -1.0]), open_angle=2 * np.pi)
    index = np.linspace(0, len(points) - 1, 300)
    at = np.arange(len(points), dtype=float)
    where = np.stack([np.interp(index, at, points[:, i]) for i in range(3)], axis=1)
    exact = np.array([edge_path_length_m(wedge, p, mic) for p in where])
    errors = [np.abs(_length_at(paths.lengths_m[k], index) - exact).max() for k in first]
    assert min(errors) < 2e-5, errors  # the top edge's path (the others: side walls' edges)
