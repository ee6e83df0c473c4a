"""Image sources against pyroomacoustics 0.10.1's ISM, region merging, pruning, errors."""

from __future__ import annotations

import warnings

import numpy as np
import pyroomacoustics as pra
import pytest
import trimesh

from sonicspec.acoustics.paths.image_sources import image_sources, planar_regions
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError, SonicspecWarning
from sonicspec.testing import rooms
from sonicspec.testing.rooms import extruded_room, shoebox

FS_HZ = 16_000
C = 343.0


def uniform_scene(verts, faces, alpha=0.2, s=0.0, tau=0.0, n_bands=1):
    return rooms.uniform_scene(verts, faces, alpha, s, tau, n_bands)


def pra_images(size, src, mic, alpha, max_order):
    room = pra.ShoeBox(
        size,
        fs=FS_HZ,
        materials=pra.Material(energy_absorption=alpha),
        max_order=max_order,
        air_absorption=False,
    )
    room.add_source(list(src))
    room.add_microphone(list(mic))
    room.image_source_model()
    s = room.sources[0]
    vis = room.visibility[0][0].astype(bool)
    images = s.images[:, vis].T
    dist = np.linalg.norm(images - np.asarray(mic), axis=1)
    # pyroomacoustics: pressure damping/r; ours: damping/(4πr) — same convention up to 4π
    amp = s.damping[0, vis] / dist / (4 * np.pi)
    return dist / C, amp, s.orders[vis]


@pytest.mark.parametrize(
    ("size", "src", "mic", "alpha"),
    [
        ([5.0, 4.0, 3.0], [1.2, 1.5, 1.1], [3.3, 2.2, 1.7], 0.3),
        ([10.0, 7.0, 3.0], [2.0, 5.1, 1.4], [7.7, 1.3, 1.9], 0.2),
    ],
)
def test_shoebox_order_2_matches_pyroomacoustics(size, src, mic, alpha):
    verts, faces = shoebox(*size)
    scene = uniform_scene(verts, faces, alpha=alpha)
    res = image_sources(scene, np.array(src), np.array([mic]), max_order=2)
    ours = res.arrivals[0]
    assert res.max_order == 2
    t_ref, a_ref, o_ref = pra_images(size, src, mic, alpha, 2)
    t_ref, a_ref, o_ref = t_ref[o_ref > 0], a_ref[o_ref > 0], o_ref[o_ref > 0]
    assert len(ours) == len(t_ref) == 6 + 18
    order = np.argsort(t_ref, kind="stable")
    t_ref, a_ref, o_ref = t_ref[order], a_ref[order], o_ref[order]
    assert np.all(np.abs(ours.times_s - t_ref) * FS_HZ <= 1.0)
    assert np.all(np.abs(20 * np.log10(ours.amplitudes[:, 0] / a_ref)) <= 0.5)
    assert np.array_equal(np.sort(ours.order), np.sort(o_ref))
    # direction of arrival is a unit vector towards the image
    np.testing.assert_allclose(np.linalg.norm(ours.directions, axis=1), 1.0)


def test_order_3_shoebox_count_and_amplitudes():
    size, src, mic, alpha = [6.0, 5.0, 3.0], [1.0, 1.7, 1.2], [4.2, 3.1, 1.5], 0.1
    verts, faces = shoebox(*size)
    scene = uniform_scene(verts, faces, alpha=alpha, s=0.2)
    ours = image_sources(scene, np.array(src), np.array([mic]), max_order=3).arrivals[0]
    _, a_ref, o_ref = pra_images(size, src, mic, alpha, 3)
    keep = o_ref > 0
    assert len(ours) == keep.sum() == 6 + 18 + 38
    # scattering removes (1-s) of the specular energy per bounce: √(1-s) in amplitude
    ref = np.sort(a_ref[keep] * np.sqrt(0.8) ** o_ref[keep])
    np.testing.assert_allclose(np.sort(ours.amplitudes[:, 0]), ref, rtol=1e-5)  # pra: float32


@pytest.mark.parametrize("levels", [2, 3])  # 32 triangles per wall: barycentric; 128: Embree probe
def test_subdivided_walls_merge_into_six_regions_and_give_the_same_images(levels):
    verts, faces = shoebox(5.0, 4.0, 3.0)
    fine_v, fine_f = verts, faces
    for _ in range(levels):
        fine_v, fine_f = trimesh.remesh.subdivide(fine_v, fine_f)
    coarse = uniform_scene(verts, faces, alpha=0.3)
    fine = uniform_scene(fine_v, fine_f, alpha=0.3)
    assert planar_regions(coarse).n_regions == 6
    assert planar_regions(fine).n_regions == 6
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    a = image_sources(coarse, src, mic, max_order=3).arrivals[0]
    b = image_sources(fine, src, mic, max_order=3).arrivals[0]
    assert len(a) == len(b)
    np.testing.assert_allclose(a.times_s, b.times_s, rtol=1e-12)
    np.testing.assert_allclose(a.amplitudes, b.amplitudes, rtol=1e-12)


def test_different_materials_on_one_plane_stay_separate_regions():
    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces)
    alpha = np.array(scene.absorption)
    alpha[0] = 0.5  # one floor triangle of another material
    other = AcousticScene(verts, faces, alpha, scene.scattering, scene.transmission)
    assert planar_regions(other).n_regions == 7


@pytest.mark.parametrize("levels", [0, 3])
def test_l_room_images_need_visibility(levels):
    poly = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    verts, faces = extruded_room(poly, [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)], 3.0)
    for _ in range(levels):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    scene = uniform_scene(verts, faces)
    src = np.array([5.5, 1.0, 1.5])
    rcv = np.array([[1.0, 5.5, 1.5]])
    arr = image_sources(scene, src, rcv, max_order=1).arrivals[0]
    # Brute-force oracle: mirror in every region, check the reflection point by the
    # polygon of the wall and the two segments by an independent trimesh ray query.
    mesh = trimesh.Trimesh(verts, faces, process=False)
    regions = planar_regions(scene)
    expected = []
    for p in range(regions.n_regions):
        n, d = regions.normals[p], regions.plane_d[p]
        img = src - 2 * (n @ src - d) * n
        vec = img - rcv[0]
        t = (d - n @ rcv[0]) / (n @ vec)
        if not 0 < t < 1:
            continue
        q = rcv[0] + t * vec
        fcs = regions.region_faces[regions.region_start[p] : regions.region_start[p + 1]]
        if (
            not trimesh.triangles.points_to_barycentric(
                mesh.triangles[fcs], np.repeat(q[None], len(fcs), 0)
            )
            .min(axis=1)
            .max()
            >= -1e-9
        ):
            continue
        ok = True
        for a, b in [(src, q), (q, rcv[0])]:
            dirn = (b - a) / np.linalg.norm(b - a)
            locs, _, _ = mesh.ray.intersects_location([a + 1e-4 * dirn], [dirn])
            dist = np.linalg.norm(locs - a, axis=1)
            if np.any((dist > 1e-3) & (dist < np.linalg.norm(b - a) - 1e-3)):
                ok = False
        if ok:
            expected.append(np.linalg.norm(vec))
    assert len(expected) >= 2  # floor and ceiling at least
    np.testing.assert_allclose(np.sort(arr.path_length_m), np.sort(expected), rtol=1e-12)


def test_max_path_length_prunes_long_paths_only():
    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces)
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    full = image_sources(scene, src, mic, max_order=3).arrivals[0]
    cut = image_sources(scene, src, mic, max_order=3, max_path_length_m=10.0).arrivals[0]
    np.testing.assert_allclose(cut.path_length_m, full.path_length_m[full.path_length_m <= 10.0])


def test_many_receivers_at_once_equal_one_by_one():
    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces, n_bands=2)
    src = np.array([1.2, 1.5, 1.1])
    mics = np.array([[3.3, 2.2, 1.7], [4.1, 0.5, 2.5], [0.4, 3.5, 0.3]])
    together = image_sources(scene, src, mics, max_order=2).arrivals
    for i in range(3):
        alone = image_sources(scene, src, mics[i : i + 1], max_order=2).arrivals[0]
        np.testing.assert_array_equal(alone.times_s, together[i].times_s)
        np.testing.assert_array_equal(alone.amplitudes, together[i].amplitudes)


def test_candidate_limit_warns_and_reports_completed_order():
    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces)
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    with pytest.warns(SonicspecWarning, match="stopping at order 2"):  # the unpruned search
        res = image_sources(scene, src, mic, max_order=3, max_candidates=100, beams=False)
    assert res.max_order == 2
    assert res.arrivals[0].order.max() == 2


@pytest.mark.parametrize("beams", [False, True])
@pytest.mark.parametrize("limit", [5, 20, 40, 100, 140, 149, 150, 200])
def test_candidate_limit_decided_early_as_by_building_the_images(monkeypatch, limit: int,
                                                                 beams: bool):
    """The count that stops an order before its images are built gives the same decision and
    arrivals as building them (limits around the 150 order-3 candidates of this shoebox, with
    a path-length limit that keeps every one of them, and ones that keep only some: at 12 m,
    135 of them, so a limit of 140 must let order 3 be built)."""
    from sonicspec.acoustics.paths import image_sources as ism

    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces)
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    for max_path in (1000.0, 20.0, 12.0):
        runs = []
        for early in (True, False):
            if not early:
                monkeypatch.setattr(ism, "_provably_too_many", lambda *a, **k: False)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                res = image_sources(scene, src, mic, max_order=3, max_candidates=limit,
                                    max_path_length_m=max_path, beams=beams)
            runs.append((res.max_order, res.arrivals[0].times_s.tobytes(),
                         [str(w.message) for w in caught]))
            monkeypatch.undo()
        assert runs[0] == runs[1]


def test_image_source_errors():
    verts, faces = shoebox(5.0, 4.0, 3.0)
    scene = uniform_scene(verts, faces)
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    with pytest.raises(AcousticsError, match="max_order: expected an integer >= 0"):
        image_sources(scene, src, mic, max_order=-1)
    other = uniform_scene(*shoebox(5.0, 4.0, 3.0))
    bad_regions = planar_regions(
        AcousticScene(*trimesh.remesh.subdivide(verts, faces), *(np.zeros((48, 1)),) * 3)
    )
    with pytest.raises(AcousticsError, match="regions: expected the planar regions"):
        image_sources(other, src, mic, regions=bad_regions)
    with pytest.raises(AcousticsError, match="speed_of_sound_m_s: expected > 0"):
        image_sources(scene, src, mic, speed_of_sound_m_s=-1.0)


def test_image_sources_are_reciprocal():
    poly = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    verts, faces = extruded_room(poly, [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)], 3.0)
    scene = uniform_scene(verts, faces, alpha=0.25, s=0.1)
    a, b = np.array([5.5, 1.0, 1.5]), np.array([1.2, 2.2, 1.1])
    fwd = image_sources(scene, a, b[None], max_order=3).arrivals[0]
    bwd = image_sources(scene, b, a[None], max_order=3).arrivals[0]
    assert len(fwd) == len(bwd) > 10
    np.testing.assert_allclose(fwd.times_s, bwd.times_s, rtol=1e-12)
    # equal path lengths can tie (different orders): match by (order, time)
    i = np.lexsort((np.round(fwd.times_s, 9), fwd.order))
    j = np.lexsort((np.round(bwd.times_s, 9), bwd.order))
    np.testing.assert_allclose(fwd.amplitudes[i], bwd.amplitudes[j], rtol=1e-9)


def test_noisy_scan_walls_merge_with_scan_tolerances():
    """3 mm vertex noise: exact tolerances keep every triangle apart, scan tolerances merge
    the walls and recover the clean room's image sources to within the noise."""
    verts, faces = shoebox(5.0, 4.0, 3.0)
    for _ in range(2):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    noisy = verts + np.random.default_rng(0).normal(0.0, 0.003, verts.shape)
    clean_scene = uniform_scene(verts, faces, alpha=0.3)
    noisy_scene = uniform_scene(noisy, faces, alpha=0.3)
    assert planar_regions(noisy_scene).n_regions > 100
    regions = planar_regions(noisy_scene, angle_tol_rad=0.1, distance_tol_m=0.02)
    assert regions.n_regions == 6
    src, mic = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    clean = image_sources(clean_scene, src, mic, max_order=2).arrivals[0]
    scan = image_sources(noisy_scene, src, mic, max_order=2, regions=regions).arrivals[0]
    assert len(scan) == len(clean) == 24
    np.testing.assert_allclose(scan.path_length_m, clean.path_length_m, atol=0.01)


def _reach_every_vertex(scene, regions, tol):
    """Reference: the side test over every vertex of every region (no outline reduction)."""
    reach = np.zeros((2, regions.n_regions, regions.n_regions), dtype=bool)
    for p in range(regions.n_regions):
        fcs = regions.region_faces[regions.region_start[p] : regions.region_start[p + 1]]
        pts = scene.vertices[scene.faces[fcs]].reshape(-1, 3)
        dist = regions.normals @ pts.T - regions.plane_d[:, None]
        reach[0, :, p] = dist.max(axis=1) > tol
        reach[1, :, p] = dist.min(axis=1) < -tol
    return reach


def test_reach_table_from_region_outlines_matches_every_vertex():
    """Pruning uses only each region's outline corners: on a finely tessellated L-room the
    table equals the every-vertex one; on a noisy scan it only ever adds reachable pairs."""
    from sonicspec.acoustics.paths.image_sources import _reach_tables

    poly = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    verts, faces = extruded_room(poly, [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)], 3.0)
    for _ in range(3):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    scene = uniform_scene(verts, faces)
    regions = planar_regions(scene)
    got = _reach_tables(scene, regions, scene.eps_m)
    expected = _reach_every_vertex(scene, regions, scene.eps_m)
    assert expected.any() and not expected.all()  # the re-entrant corner prunes something
    np.testing.assert_array_equal(got, expected)

    noisy = verts + np.random.default_rng(1).normal(0.0, 0.003, verts.shape)
    noisy_scene = uniform_scene(noisy, faces)
    regions = planar_regions(noisy_scene, angle_tol_rad=0.1, distance_tol_m=0.02)
    got = _reach_tables(noisy_scene, regions, noisy_scene.eps_m)
    expected = _reach_every_vertex(noisy_scene, regions, noisy_scene.eps_m)
    assert np.all(got | ~expected)  # never prunes a pair the vertices say is reachable


def test_coefficient_classes_partition_faces_by_identical_rows():
    """Faces share a class exactly when their absorption, scattering and transmission rows
    are identical, also for rows that differ in one band by the smallest float step; the
    representative face of each class has that class."""
    verts, faces = shoebox(4.0, 3.0, 2.5)
    for _ in range(3):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    rng = np.random.default_rng(5)
    table = rng.uniform(0.05, 0.6, (5, 3, 2))
    table[4] = table[3]
    table[4, 1, 1] = np.nextafter(table[3, 1, 1], 1.0)  # one ulp apart in one band
    pick = rng.integers(0, 5, len(faces))
    scene = AcousticScene(verts, faces, table[pick, 0], table[pick, 1], table[pick, 2] * 0.1)
    got, first = scene.coefficient_classes()
    assert np.array_equal(got[first], np.arange(len(first)))
    assert scene.coefficient_classes() is scene.coefficient_classes()  # computed once
    coef = np.concatenate([scene.absorption, scene.scattering, scene.transmission], axis=1)
    _, exact = np.unique(coef, axis=0, return_inverse=True)
    exact = exact.reshape(-1)
    # Same partition: a one-to-one map between the two labelings.
    pairs = set(zip(got.tolist(), exact.tolist(), strict=True))
    assert len(pairs) == len(set(got.tolist())) == len(set(exact.tolist())) == 5


@pytest.mark.parametrize("levels", [0, 3])
def test_compiled_prefilter_keeps_every_valid_path_and_drops_most_pairs(monkeypatch, levels):
    """The compiled prefilter of each order's (image, receiver) pairs only narrows what the
    exact tests see: in a furnished L room (two boxes, one rotated; subdivided 3 times, its
    walls become regions of more than 64 triangles, tested by probe rays) the arrivals to
    order 3 are the same bytes as with every pair passed through, from several positions;
    unsubdivided, it passes on under a third of the pairs (the probe-tested regions of the
    subdivided room are left to the exact pass)."""
    from sonicspec.acoustics.paths import _image_source_kernels as KI
    from sonicspec.geometry.procedural import add_obstacles, box_obstacle, l_shape

    room = l_shape([6.0, 5.0, 2.7], [2.5, 2.0])
    room = add_obstacles(room, [box_obstacle([1.5, 1.5, 0.4], [1.0, 0.6, 0.8]),
                                box_obstacle([3.0, 3.5, 0.5], [0.8, 0.8, 1.0], yaw_deg=30.0)])
    verts, faces = room.vertices, room.faces
    for _ in range(levels):
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    scene = uniform_scene(verts, faces, alpha=0.3, s=0.1)
    regions = planar_regions(scene)
    rng = np.random.default_rng(levels)
    srcs = np.c_[rng.uniform(0.3, 3.2, 4), rng.uniform(0.3, 2.7, 4), rng.uniform(1.2, 2.4, 4)]
    rcvs = np.c_[rng.uniform(0.3, 3.2, (4, 2)).ravel()[:4], rng.uniform(0.3, 2.7, 4),
                 rng.uniform(0.3, 2.4, 4)]
    real = KI.last_reflection_prefilter
    kept = []

    def counting(*args):
        real(*args)
        kept.append(args[-1].mean())

    def everything(*args):
        args[-1][:] = True

    for src, rcv in zip(srcs, rcvs, strict=True):
        runs = []
        for prefilter in (counting, everything):
            monkeypatch.setattr(KI, "last_reflection_prefilter", prefilter)
            res = image_sources(scene, src, rcv[None], max_order=3, regions=regions,
                                max_path_length_m=60.0, beams=False)
            a = res.arrivals[0]
            runs.append((res.max_order, a.times_s.tobytes(), a.amplitudes.tobytes(),
                         a.directions.tobytes()))
        assert runs[0] == runs[1]
        assert runs[0][0] == 3 and len(runs[0][1]) > 8 * 8
    if levels == 0:
        assert np.mean(kept) < 1 / 3, kept


def test_each_images_isometry_maps_the_source_to_its_image_and_moves_it_with_the_source():
    """``Arrivals.isometry`` (issue 18, moving microphones): ``M @ source + b`` is the image
    the path comes from (direction of arrival times length from the receiver), ``M`` is
    orthogonal with determinant ``(-1)^order``, and the same map sends a moved source to the
    image the image-source method finds for it (pyroomacoustics' images, order 3)."""
    size = [5.0, 4.0, 3.0]
    verts, faces = shoebox(*size)
    scene = uniform_scene(verts, faces)
    src, rcv = np.array([1.2, 1.5, 1.1]), np.array([[3.3, 2.2, 1.7]])
    arr = image_sources(scene, src, rcv, max_order=3).arrivals[0]
    m, b = arr.isometry[:, :, :3], arr.isometry[:, :, 3]
    image = rcv[0] + arr.directions * arr.path_length_m[:, None]
    np.testing.assert_allclose(np.einsum("nij,j->ni", m, src) + b, image, atol=1e-9)
    np.testing.assert_allclose(m @ np.transpose(m, (0, 2, 1)),
                               np.broadcast_to(np.eye(3), m.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m), (-1.0) ** arr.order, atol=1e-12)
    moved = src + np.array([0.7, -0.4, 0.3])
    predicted = np.einsum("nij,j->ni", m, moved) + b
    lengths, _, _ = pra_images(size, moved, rcv[0], 0.2, 3)
    distance = np.linalg.norm(predicted - rcv[0], axis=1)
    # every predicted image is one pyroomacoustics finds for the moved source (the moved
    # source may see more paths; the ones it shares are where the maps say; pyroomacoustics
    # keeps its images in single precision)
    assert np.min(np.abs(distance[:, None] - lengths[None, :] * C), axis=1).max() < 1e-5
