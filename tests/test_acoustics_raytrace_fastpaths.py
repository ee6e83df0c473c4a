"""The tracer's shortcuts change its cost, never its result: each against the slow path."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.acoustics.late import _trace_kernels as K
from sonicspec.acoustics.late import raytrace
from sonicspec.acoustics.late.raytrace import RayTraceSettings, receiver_clearance_m, trace_rays
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.testing.rooms import (
    extruded_room,
    flutter_scene,
    partitioned_shoebox,
    shoebox,
    uniform_scene,
)

L_ROOM = ([(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)],
          [(0, 1, 2), (0, 2, 3), (0, 3, 5), (3, 4, 5)])


def histograms(results):
    return [(r.histogram.energy, r.histogram.direction_sum, r.histogram.departure_sum)
            for r in results]


def assert_same_histograms(results_a, results_b, rtol: float = 1e-12) -> None:
    """Energies and both direction sums of every receiver agree (up to summation order)."""
    for a, b in zip(histograms(results_a), histograms(results_b), strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_allclose(x, y, rtol=rtol, atol=1e-30)


def test_receiver_spheres_together_equal_one_by_one():
    """Twelve receivers in one trace (enough for the sphere tests to visit only those within
    reach along the receivers' widest axis), then one at a time (every receiver tested): the
    same sums. Receiver spheres only (no rain), some receivers near walls (small radius cap)."""
    from sonicspec.acoustics.late._trace_kernels import CULL_ABOVE

    scene = uniform_scene(*shoebox(6.0, 5.0, 3.0), alpha=0.3, s=0.4, n_bands=2)
    src = np.array([1.0, 1.0, 1.5])
    rcvs = np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0], [2.5, 4.0, 0.5], [5.9, 4.9, 2.9],
                     [0.2, 2.5, 1.5], [3.0, 2.5, 1.5], [3.2, 2.6, 1.4], [0.5, 0.5, 0.5],
                     [5.5, 4.5, 2.5], [1.5, 4.8, 1.0], [4.5, 0.3, 2.7], [2.0, 2.0, 2.0]])
    assert len(rcvs) > CULL_ABOVE
    settings = RayTraceSettings(n_rays=600, max_time_s=0.3, diffuse_rain=False,
                                specular_order_excluded=0)
    together = trace_rays(scene, src, rcvs, np.random.default_rng(2), settings)
    for i in range(len(rcvs)):
        (alone,) = trace_rays(scene, src, rcvs[i:i + 1], np.random.default_rng(2), settings)
        assert alone.histogram.energy.sum() > 0
        assert_same_histograms([alone], [together[i]], rtol=1e-9)


@pytest.mark.parametrize("flip", [False, True])
def test_convex_room_planes_face_inwards_whatever_the_winding(flip: bool):
    verts, faces = shoebox(4.0, 3.0, 2.5)
    scene = uniform_scene(verts, faces[:, ::-1] if flip else faces, n_bands=1)
    normals, offsets = raytrace._convex_planes(scene)
    assert np.all(np.array([2.0, 1.5, 1.2]) @ normals.T - offsets > 0)
    assert np.any(np.array([5.0, 1.5, 1.2]) @ normals.T - offsets < 0)  # outside


def traced_before_and_after(monkeypatch, name: str, value, scene, src, rcvs, settings,
                            seed: int) -> tuple[list, list]:
    """The same trace (same seed) before and after setting ``raytrace.<name>`` to ``value``:
    for shortcuts that must not change the sums."""
    before = trace_rays(scene, src, rcvs, np.random.default_rng(seed), settings)
    monkeypatch.setattr(raytrace, name, value)
    return before, trace_rays(scene, src, rcvs, np.random.default_rng(seed), settings)


def test_non_convex_room_or_transmission_keeps_every_shadow_ray():
    scene = uniform_scene(*extruded_room(*L_ROOM, 3.0), n_bands=1)
    assert raytrace._convex_planes(scene) is None
    glass = uniform_scene(*shoebox(4.0, 3.0, 2.5), tau=0.1, n_bands=1)
    assert raytrace._convex_planes(glass) is None


def test_convex_shortcut_gives_what_the_shadow_rays_give(monkeypatch):
    scene = uniform_scene(*shoebox(6.0, 5.0, 3.0), alpha=0.2, s=0.6, n_bands=2)
    src = np.array([1.0, 1.0, 1.5])
    rcvs = np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0], [5.95, 4.95, 0.05]])
    settings = RayTraceSettings(n_rays=500, max_time_s=0.4)
    assert_same_histograms(*traced_before_and_after(
        monkeypatch, "_CONVEX_MAX_FACES", 0, scene, src, rcvs, settings, seed=4))


@pytest.mark.parametrize("room", ["shoebox", "L"])
def test_clearance_shortcut_matches_the_sampled_clearance(room: str):
    verts, faces = shoebox(6.0, 6.0, 3.0) if room == "shoebox" else extruded_room(*L_ROOM, 3.0)
    scene = uniform_scene(verts, faces, n_bands=1)
    rng = np.random.default_rng(0)
    points = np.c_[rng.uniform(0.05, 2.95, 200), rng.uniform(0.05, 5.95, 200),
                   rng.uniform(0.05, 2.95, 200)]
    sampled = receiver_clearance_m(scene, points)
    for limit in (0.3, 1.0):
        short = raytrace._clearance_below(scene, points, limit)
        assert np.array_equal(np.minimum(short, limit), np.minimum(sampled, limit))
        assert 0 < np.count_nonzero(np.isinf(short)) < len(points)  # some rays were skipped


def test_without_directions_the_energies_are_the_same_bytes():
    scene = uniform_scene(*shoebox(6.0, 5.0, 3.0), alpha=0.3, s=0.4, n_bands=3)
    src = np.array([1.0, 1.0, 1.5])
    rcvs = np.array([[4.0, 3.0, 1.2], [5.0, 1.0, 2.0], [2.5, 4.0, 0.5], [3.0, 2.5, 1.5],
                     [1.5, 3.5, 2.5]])
    settings = RayTraceSettings(n_rays=500, max_time_s=0.3, rain_receivers_per_hit=2)
    full = trace_rays(scene, src, rcvs, np.random.default_rng(8), settings)
    bare = trace_rays(scene, src, rcvs, np.random.default_rng(8),
                      RayTraceSettings(n_rays=500, max_time_s=0.3, rain_receivers_per_hit=2,
                                       directions=False))
    for a, b in zip(full, bare, strict=True):
        assert a.histogram.energy.tobytes() == b.histogram.energy.tobytes()
        assert np.all(np.isfinite(a.histogram.direction_sum))
        assert np.all(np.isnan(b.histogram.direction_sum))
        assert np.all(np.isnan(b.histogram.departure_sum))


def test_roulette_through_transmitting_walls_is_unbiased():
    """Blocked shadow rays are walked through the wall with probability max τ and weighted by
    1/max τ. The rain that reaches the closed neighbouring room through the partition (the
    energy minus a run in which no blocked shadow ray is walked) matches walking every one of
    them. Ray paths use their own random stream, so all runs trace the very same rays."""
    verts, faces = partitioned_shoebox(8.0, 4.0, 3.0, 4.0)
    tau = np.zeros((len(faces), 2))
    tau[-2:] = [0.05, 0.2]
    scene = AcousticScene(verts, faces, np.full((len(faces), 2), 0.2),
                          np.full((len(faces), 2), 0.5), tau)
    src, rcv = np.array([1.5, 2.0, 1.5]), np.array([[6.5, 2.2, 1.4]])
    settings = RayTraceSettings(n_rays=3000, max_time_s=0.4, specular_order_excluded=0)
    energy = {}
    for name, walk in (("roulette", None), ("every", 1.0), ("none", 1e-300)):
        if walk is not None:
            scene.max_transmission = walk  # the walk probability is min(1, max τ)
        (res,) = trace_rays(scene, src, rcv, np.random.default_rng(5), settings)
        energy[name] = res.histogram.energy.sum(axis=0)
    through_wall = energy["every"] - energy["none"]
    assert np.all(through_wall > 0.03 * energy["every"])
    np.testing.assert_allclose(energy["roulette"] - energy["none"], through_wall, rtol=0.05)


def test_walking_blocked_shadow_rays_in_batches_gives_the_same_sums(monkeypatch):
    """Blocked shadow rays chosen by the roulette are walked through the walls together; walking
    them after every bounce step instead adds the same contributions (sums up to rounding)."""
    verts, faces = extruded_room(*L_ROOM, 3.0)
    scene = uniform_scene(verts, faces, alpha=0.2, s=0.6, tau=0.3, n_bands=2)
    src = np.array([1.0, 1.0, 1.5])
    rcvs = np.array([[5.0, 1.5, 1.2], [1.5, 5.0, 2.0], [2.0, 2.0, 0.5]])
    settings = RayTraceSettings(n_rays=400, max_time_s=0.3)
    batched, stepwise = traced_before_and_after(
        monkeypatch, "_WALK_BATCH", 1, scene, src, rcvs, settings, seed=6)
    assert batched[1].histogram.energy.sum() > 0  # round the corner from the source
    assert_same_histograms(batched, stepwise)


def test_visible_air_volume_of_a_ball_cut_by_walls():
    """The tabulated visible-air volume of a receiver's ball against the closed form: a ball of
    radius R whose centre is h < R from one wall loses a cap of height R − h; near a corner it
    loses two (overlapping only beyond the radii tested); within the clearance, the whole ball."""
    scene = uniform_scene(*shoebox(6.0, 5.0, 3.0), n_bands=1)
    receivers = np.array([[3.0, 2.5, 1.0], [0.6, 0.8, 1.5]])
    cap = np.array([2.0, 0.75])
    _, volume = raytrace._visible_air(scene, receivers, cap)
    radii = np.linspace(0.0, 1.0, volume.shape[1])[None, :] * cap[:, None]
    expected = np.stack([ball_minus_caps(radii[0], [1.0]), ball_minus_caps(radii[1], [0.6])])
    big = radii > 0.3  # (the tracer uses the exact ball below the clearance)
    np.testing.assert_allclose(volume[big], expected[big], rtol=0.01)
    assert volume[0, -1] < 0.95 * 4.0 / 3.0 * np.pi * 2.0**3  # the floor cut something off


def ball_minus_caps(r, depths):
    """Volume of a ball of radius ``r`` cut by planes at ``depths`` from its centre."""
    v = 4.0 / 3.0 * np.pi * r**3
    for h in depths:
        q = np.clip(r - h, 0.0, None)
        v = v - np.pi * q**2 * (3 * r - q) / 3.0
    return v


def test_visible_air_stops_at_a_thin_partition():
    """Air behind a single-sheet partition is not the receiver's: the ball 0.5 m from it
    loses the cap beyond it, though there is air on the other side."""
    scene = uniform_scene(*partitioned_shoebox(8.0, 5.0, 3.0, 4.0), n_bands=1)
    receivers = np.array([[3.5, 2.5, 1.5]])
    _, volume = raytrace._visible_air(scene, receivers, np.array([1.2]))
    np.testing.assert_allclose(volume[0, -1], ball_minus_caps(1.2, [0.5]), rtol=0.01)


def test_cube_cells_are_indexed_as_the_kernel_looks_them_up():
    """Every cell's centre direction maps back to its own index, and the cells tile the
    sphere (solid angles sum to 4π)."""
    dirs, solid = raytrace._cube_cells(5)
    found = [K.cube_cell(*d, 5) for d in dirs]
    np.testing.assert_array_equal(found, np.arange(len(dirs)))
    assert solid.sum() == pytest.approx(4.0 * np.pi, rel=1e-12)


def test_free_air_ball_does_not_count_the_room_behind_a_partition():
    """Two rooms behind a partition that transmits nothing, the source in the left one. A
    receiver in the right room 0.5 m from the partition, with a ball that reaches 2 m into
    the source's room, gets nothing but the map's slivers (cells whose centre ray meets the
    partition a little farther than their edge does): under 0.1 % of what its mirror image
    0.5 m on the source's side gets — which the same ball measures as the small sphere does."""
    verts, faces = partitioned_shoebox(8.0, 5.0, 3.0, 4.0)
    scene = uniform_scene(verts, faces, alpha=0.1, s=0.3, n_bands=1)
    src, rcvs = np.array([2.0, 2.5, 1.5]), np.array([[4.5, 2.5, 1.5], [3.5, 2.5, 1.5]])
    totals = []
    for ball in (False, True):
        settings = RayTraceSettings(n_rays=2000, max_time_s=0.3, specular_order_excluded=0,
                                    free_air_volume=ball,
                                    max_receiver_radius_m=2.5 if ball else 1.0)
        res = trace_rays(scene, src, rcvs, np.random.default_rng(3), settings)
        totals.append([r.histogram.energy.sum() for r in res])
    (_, near_small), (behind, near_ball) = totals
    assert behind < 1e-3 * near_ball
    assert near_ball == pytest.approx(near_small, rel=0.03)


def test_free_air_ball_measures_the_same_late_field():
    """A flutter room (absorbing ceiling, hard walls, scattering 0.1): the late-detection ball
    grown to 2.5 m through floor and ceiling, with its free-air volume, gives the energy of the
    clearance-capped sphere (4 seeds each; the seed-to-seed spread of each mean is 1–2 %)."""
    scene = flutter_scene()
    src, rcv = np.array([2.0, 2.0, 1.5]), np.array([[7.5, 5.0, 1.5]])
    windows = []
    for ball in (False, True):
        settings = RayTraceSettings(n_rays=8000, max_time_s=0.6, splitting=1.0,
                                    specular_order_excluded=1, free_air_volume=ball,
                                    max_receiver_radius_m=2.5 if ball else 1.0)
        sums = []
        for seed in range(4):
            (res,) = trace_rays(scene, src, rcv, np.random.default_rng(seed), settings)
            e = res.histogram.energy
            sums.append([e[50:200].sum(axis=0), e[200:].sum(axis=0)])
        windows.append(np.mean(sums, axis=0))
    np.testing.assert_allclose(windows[1], windows[0], rtol=0.05)
