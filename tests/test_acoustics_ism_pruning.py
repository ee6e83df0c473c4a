"""Pruning of the image-source search (issue 27, item 6): beams and the last order are exact
(the same arrivals, byte for byte, as the unpruned search), scan tolerances merge a noisy
room's walls into flat mirrors without chaining round curved surfaces, and the audibility
floor drops only what it promises to."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sonicspec.acoustics.paths.image_sources import image_sources, planar_regions
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.geometry.procedural import add_obstacles, box_obstacle, l_shape, shoebox


def scene_of(v, f, alpha=0.1, s=0.05) -> AcousticScene:
    n = len(f)
    return AcousticScene(np.asarray(v, float), np.asarray(f), np.full((n, 2), alpha),
                         np.full((n, 2), s), np.zeros((n, 2)))


def furnished(levels: int, jitter_m: float = 0.0):
    room = l_shape([6.0, 5.0, 2.7], [2.5, 2.0])
    room = add_obstacles(room, [box_obstacle([1.5, 1.5, 0.4], [1.0, 0.6, 0.8]),
                                box_obstacle([3.0, 3.5, 0.5], [0.8, 0.8, 1.0], yaw_deg=30.0)])
    v, f = room.vertices, room.faces
    for _ in range(levels):
        v, f = trimesh.remesh.subdivide(v, f)
    if jitter_m:
        v = v + np.random.default_rng(3).uniform(-jitter_m, jitter_m, v.shape)
    return v, f


def arrivals_bytes(result):
    return [tuple(x.tobytes() for x in (a.times_s, a.amplitudes, a.directions, a.order,
                                        a.isometry)) for a in result.arrivals]


@pytest.mark.parametrize("room", ["shoebox", "furnished", "jittered"])
def test_pruned_search_gives_the_unpruned_arrivals(room: str) -> None:
    if room == "shoebox":
        v, f = shoebox([5.0, 4.0, 3.0]).vertices, shoebox([5.0, 4.0, 3.0]).faces
    elif room == "furnished":
        v, f = furnished(1)
    else:  # every triangle its own mirror: the unpruned order 3 is still feasible here
        box = shoebox([5.0, 4.0, 3.0])
        v, f = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, max_edge=3.5)
        v = v + np.random.default_rng(0).uniform(-0.002, 0.002, v.shape)
    scene = scene_of(v, f)
    regions = planar_regions(scene)
    rng = np.random.default_rng(7)
    for _ in range(3):
        src = np.array([rng.uniform(0.3, 2.3), rng.uniform(0.3, 1.8), rng.uniform(0.5, 2.2)])
        rcv = np.c_[rng.uniform(0.3, 2.3, 3), rng.uniform(0.3, 1.8, 3), rng.uniform(0.5, 2.2, 3)]
        pruned = image_sources(scene, src, rcv, max_order=3, regions=regions,
                               max_path_length_m=80.0)
        full = image_sources(scene, src, rcv, max_order=3, regions=regions,
                             max_path_length_m=80.0, beams=False, max_candidates=10**7)
        assert pruned.max_order == full.max_order == 3
        assert arrivals_bytes(pruned) == arrivals_bytes(full)
        assert sum(len(a) for a in pruned.arrivals) > 20
        assert sum(pruned.candidates) < sum(full.candidates)


def test_a_jittered_furnished_room_reaches_order_3_within_memory() -> None:
    """±2 mm on every vertex of a furnished L-room cut into 2,800 triangles: with exact mirrors
    (every triangle its own) the unpruned search's order 2 alone has millions of candidates;
    pruned, with the presets' mirror tolerance, order 3 takes thousands."""
    v, f = furnished(2, jitter_m=0.002)
    scene = scene_of(v, f)
    src, rcv = np.array([0.8, 0.6, 1.5]), np.array([[2.8, 2.4, 1.2], [0.5, 2.2, 1.6]])
    exact = planar_regions(scene)
    assert exact.n_regions > 0.9 * scene.n_faces  # noise: no two triangles merge
    merged = planar_regions(scene, angle_tol_rad=0.5, distance_tol_m=0.01)
    clean = planar_regions(scene_of(*furnished(2)))
    assert merged.n_regions <= clean.n_regions + 10
    res = image_sources(scene, src, rcv, max_order=3, regions=merged, max_path_length_m=100.0)
    assert res.max_order == 3 and res.stopped is None
    assert max(res.candidates) < 200_000  # ~50 B per candidate and level: a few MB
    # the unpruned search with the old cap stops at order 1 or 2
    with pytest.warns(UserWarning, match="candidates; stopping at order"):
        old = image_sources(scene, src, rcv, max_order=3, regions=exact,
                            max_path_length_m=100.0, beams=False)
    assert old.max_order < 3
    # the merged room's arrivals are the clean room's within the noise
    ref = image_sources(scene_of(*furnished(2)), src, rcv, max_order=3, regions=clean,
                        max_path_length_m=100.0)
    got, want = np.sort(res.arrivals[0].path_length_m), np.sort(ref.arrivals[0].path_length_m)
    assert abs(len(got) - len(want)) <= 0.1 * len(want)
    common = min(len(got), len(want))
    assert np.median(np.abs(got[:common] - want[:common])) < 0.02


def test_scan_tolerances_do_not_chain_round_a_curved_surface() -> None:
    """A finely faceted cylinder: neighbouring facets are within the angle tolerance, yet no
    region strays further than the distance tolerance from its plane."""
    cyl = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=256)
    scene = scene_of(cyl.vertices, cyl.faces)
    regions = planar_regions(scene, angle_tol_rad=0.5, distance_tol_m=0.01)
    for p in range(regions.n_regions):
        fcs = regions.region_faces[regions.region_start[p]:regions.region_start[p + 1]]
        pts = scene.vertices[scene.faces[fcs]].reshape(-1, 3)
        assert np.abs(pts @ regions.normals[p] - regions.plane_d[p]).max() <= 0.011
    assert regions.n_regions > 20  # the side splits into strips, the caps stay whole


def test_audibility_floor_drops_only_paths_below_it() -> None:
    box = shoebox([7.0, 5.0, 3.0])
    scene = scene_of(box.vertices, box.faces, alpha=0.6, s=0.2)
    src, rcv = np.array([1.0, 1.0, 1.5]), np.array([[1.6, 1.3, 1.4]])
    full = image_sources(scene, src, rcv, max_order=4)
    floor_db = 30.0
    cut = image_sources(scene, src, rcv, max_order=4, audible_floor_db=floor_db)
    assert cut.inaudible > 0 and len(cut.arrivals[0]) < len(full.arrivals[0])
    direct = 1.0 / (4 * np.pi * np.linalg.norm(rcv[0] - src))
    a, b = full.arrivals[0], cut.arrivals[0]
    kept = set(np.round(b.times_s, 12))
    dropped = np.array([t not in kept for t in np.round(a.times_s, 12)])
    assert np.all(a.amplitudes[dropped].max(axis=1) < direct * 10 ** (-floor_db / 20))
    assert set(np.round(b.times_s, 12)) <= set(np.round(a.times_s, 12))
    with pytest.raises(Exception, match="audible_floor_db: expected > 0 dB"):
        image_sources(scene, src, rcv, max_order=2, audible_floor_db=0.0)
