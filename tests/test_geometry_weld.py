"""Room models as people export them (issue 32): one object per material, seams welded on load.

The fixture is written here, as SketchUp, Blender and CAD exporters write it: an L-shaped room
(its inner corner a real diffracting edge) whose floor, ceiling, walls and window are separate
OBJ objects, each with its own copy of the vertices along the seams; the walls are cut where
the floor and ceiling are not (T-junctions along the seams); three radiators are closed boxes
standing off the wall. Normals point into the air.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import sonicspec as ss
from sonicspec.acoustics.paths.edges import diffracting_edges
from sonicspec.errors import GeometryError
from sonicspec.geometry.io import load_mesh
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.repair import leak_test, mesh_stats, weld_seams

HEIGHT = 3.0
FLOOR = [(0.0, 0.0), (6.0, 0.0), (6.0, 2.5), (3.5, 2.5), (3.5, 5.0), (0.0, 5.0)]
WINDOW = (1.0, 2.0, 1.0, 2.0)  # x from, x to, z from, z to, in the wall y = 0
RADIATORS = [((0.5, 0.05, 0.15), (1.0, 0.1, 0.6)), ((4.0, 0.05, 0.15), (1.0, 0.1, 0.6)),
             ((0.05, 3.0, 0.15), (0.1, 1.0, 0.6))]
SOURCE, MIC = (5.0, 1.0, 1.5), (1.5, 4.2, 1.6)
#: The real diffracting edges: the L's inner corner and the radiators' twelve edges each.
REAL_EDGES = 1 + 12 * len(RADIATORS)


def _quad(p0, p1, p2, p3) -> list[tuple]:
    """Two triangles of a quad given counter-clockwise as seen from the air."""
    return [(p0, p1, p2), (p0, p2, p3)]


def _wall(a, b, z0: float, z1: float) -> list[tuple]:
    """A wall panel from floor point a to b (the floor outline counter-clockwise from above),
    facing the room."""
    (ax, ay), (bx, by) = a, b
    return _quad((ax, ay, z0), (ax, ay, z1), (bx, by, z1), (bx, by, z0))


def _box(corner, size) -> list[tuple]:
    """A closed box, normals out (into the room's air)."""
    x0, y0, z0 = corner
    x1, y1, z1 = x0 + size[0], y0 + size[1], z0 + size[2]
    p = {(i, j, k): (x1 if i else x0, y1 if j else y0, z1 if k else z0)
         for i in (0, 1) for j in (0, 1) for k in (0, 1)}
    faces = []
    for quad in ([(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)], [(0, 0, 1), (1, 0, 1), (1, 1, 1),
                 (0, 1, 1)], [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)],
                 [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)], [(0, 0, 0), (0, 0, 1), (0, 1, 1),
                 (0, 1, 0)], [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)]):
        faces += _quad(*(p[c] for c in quad))
    return faces


def room_objects() -> dict[str, list[tuple]]:
    """Triangles (three points each) of every object, by material name."""
    floor_tris = [((0, 0), (6, 0), (6, 2.5)), ((0, 0), (6, 2.5), (3.5, 2.5)),
                  ((0, 0), (3.5, 2.5), (0, 2.5)), ((0, 2.5), (3.5, 2.5), (3.5, 5)),
                  ((0, 2.5), (3.5, 5), (0, 5))]
    floor = [tuple((x, y, 0.0) for x, y in t) for t in floor_tris]
    ceiling = [tuple((x, y, HEIGHT) for x, y in t[::-1]) for t in floor_tris]
    x0, x1, z0, z1 = WINDOW
    # the wall y = 0 is cut around the window and at x = 3; floor and ceiling are not
    walls = (_wall((0, 0), (x0, 0), 0, HEIGHT) + _wall((x0, 0), (x1, 0), 0, z0)
             + _wall((x0, 0), (x1, 0), z1, HEIGHT) + _wall((x1, 0), (3, 0), 0, HEIGHT)
             + _wall((3, 0), (6, 0), 0, HEIGHT))
    for a, b in zip(FLOOR[1:], FLOOR[2:] + FLOOR[:1], strict=True):
        walls += _wall(a, b, 0, HEIGHT)
    window = _wall((x0, 0), (x1, 0), z0, z1)
    radiators = [t for corner, size in RADIATORS for t in _box(corner, size)]
    return {"floor": floor, "ceiling": ceiling, "walls": walls, "window": window,
            "radiator": radiators}


def write_obj(path: Path, objects: dict[str, list[tuple]], *, merged: bool = False) -> Path:
    """An OBJ file: one ``o``/``usemtl`` object per material, each with its own vertices (the
    seams duplicated); ``merged``: one object ``room`` sharing every vertex."""
    lines = ["# written by tests/test_geometry_weld.py", "mtllib room.mtl"]
    index: dict[tuple, int] = {}
    count = 0
    if merged:
        lines.append("o room")
    for name, tris in objects.items():
        if not merged:
            lines.append(f"o {name}")
            index = {}  # every object its own copy of its vertices
        lines.append(f"usemtl {name}")
        for tri in tris:
            ids = []
            for p in tri:
                key = tuple(float(c) for c in p)
                if key not in index:
                    count += 1
                    index[key] = count
                    lines.append("v " + " ".join(f"{c:.6f}" for c in key))
                ids.append(index[key])
            lines.append("f " + " ".join(map(str, ids)))
    path.write_text("\n".join(lines) + "\n")
    return path


SAME = "plaster_on_brick"
MATERIALS = {"floor": "parquet_on_concrete", "ceiling": "plaster_on_concrete",
             "walls": "plaster_on_brick", "window": "glass_window", "radiator": "metal_sheet"}


@pytest.fixture(scope="module")
def obj_files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("exported")
    return {"split": write_obj(folder / "room.obj", room_objects()),
            "merged": write_obj(folder / "room_merged.obj", room_objects(), merged=True)}


def _materials(library: str = "sonicspec") -> dict[str, str]:
    from sonicspec.geometry.materials import material_library

    names = material_library(library).materials
    return {label: (name if name in names else SAME) for label, name in MATERIALS.items()}


def _edges(mesh: SceneMesh, **kw):
    return diffracting_edges(mesh.vertices, mesh.faces, mesh.face_normals, **kw)


def _on_a_real_edge(edges) -> np.ndarray:
    """Which edges lie on the L's inner corner or on a radiator box's edge."""
    corner = (np.abs(edges.start[:, :2] - [3.5, 2.5]).max(axis=1) < 1e-9) & (
        np.abs(edges.end[:, :2] - [3.5, 2.5]).max(axis=1) < 1e-9)
    on_box = np.zeros(len(edges), bool)
    for lo, size in RADIATORS:
        lo, hi = np.array(lo), np.array(lo) + size
        for p in (edges.start, edges.end):
            # an end of a box edge is a corner of the box: each coordinate at lo or hi
            at = (np.abs(p - lo) < 1e-9) | (np.abs(p - hi) < 1e-9)
            on_box |= at.all(axis=1)
    return corner | on_box


def test_a_room_exported_one_object_per_material_loads_closed(obj_files) -> None:
    scene = ss.Scene.from_file(obj_files["split"], materials=_materials(), up_axis="z")
    stats = mesh_stats(scene.mesh.faces, len(scene.mesh.vertices))
    assert stats.boundary_edges == 0 and stats.non_manifold_edges == 0
    assert stats.components == 1 + len(RADIATORS)  # the room and three closed boxes
    # what was welded: 16 seam vertices, 12 T-junctions (the wall cut where the floor and
    # ceiling are not, and the window's cuts), 44 open edges before
    weld = scene.weld
    assert (weld.merged_vertices, weld.t_junctions_stitched) == (16, 12)
    assert (weld.open_edges_before, weld.open_edges_after) == (44, 0)
    # each face keeps its object's label and material
    areas = scene.material_areas_m2()
    floor_area = 6 * 2.5 + 3.5 * 2.5
    assert areas[MATERIALS["floor"]] == pytest.approx(floor_area)
    assert areas[_materials()["window"]] == pytest.approx(1.0)
    assert scene.mesh.air_volume() == pytest.approx(floor_area * HEIGHT - 3 * 0.06)
    # the file as it is, not welded: the seams are open
    raw = load_mesh(obj_files["split"], up_axis="z", obj_labels=True, weld_distance_m=0.0)
    assert mesh_stats(raw.faces, len(raw.vertices)).boundary_edges == 44


def test_seams_are_never_diffracting_edges(obj_files) -> None:
    welded = load_mesh(obj_files["split"], up_axis="z", obj_labels=True)
    found = _edges(welded)
    assert found.n_found == REAL_EDGES and found.seams == 0
    assert _on_a_real_edge(found).all()
    np.testing.assert_allclose(found.open_angle, 1.5 * math.pi)
    # even unwelded, an open edge that another open edge overlaps is a seam, not a rim
    raw = load_mesh(obj_files["split"], up_axis="z", obj_labels=True, weld_distance_m=0.0)
    unwelded = _edges(raw)
    assert unwelded.n_found == REAL_EDGES and unwelded.seams == 44
    assert _on_a_real_edge(unwelded).all()


def test_the_leak_test_samples_the_navigable_air(obj_files) -> None:
    scene = ss.Scene.from_file(obj_files["split"], materials=_materials(), up_axis="z")
    report = leak_test(scene.mesh, np.random.default_rng(0), 10_000)
    assert report.origins == "navigable"
    assert report.leak_fraction == 0.0 and report.places == ()
    # unwelded, ray parity cannot tell the air from the radiators (the room is five open
    # pieces): random points of the bounding box counted 1.5 % of rays as leaking there; the
    # navigable air does not
    raw = load_mesh(obj_files["split"], up_axis="z", obj_labels=True, weld_distance_m=0.0)
    assert leak_test(raw, np.random.default_rng(0), 10_000).leak_fraction == 0.0
    # from the job's own positions, through the API
    given = scene.leak_test(2000, points=[SOURCE, MIC])
    assert given.origins == "given" and given.leak_fraction == 0.0
    assert scene.leak_test(2000, seed=1).origins == "navigable"


def test_a_leak_is_reported_where_it_is(obj_files) -> None:
    objects = room_objects()
    del objects["window"]  # a 1 m x 1 m hole in the wall y = 0
    path = write_obj(obj_files["split"].parent / "no_window.obj", objects)
    mesh = load_mesh(path, up_axis="z", obj_labels=True)
    report = leak_test(mesh, np.random.default_rng(0), 10_000)
    assert report.leak_fraction > 0.005
    top = report.places[0]
    assert top.kind == "hole" and top.rays == report.escaped + report.backface
    np.testing.assert_allclose(top.where_m, [1.5, 0.0, 1.5], atol=1e-9)
    assert top.size_m == pytest.approx(math.sqrt(2)) and top.label == "walls"
    assert "through a hole of 1.41 m at [1.50, 0.00, 1.50]" in report.where()


def test_edges_kept_are_the_important_ones_for_the_job(obj_files) -> None:
    mesh = load_mesh(obj_files["split"], up_axis="z", obj_labels=True)
    # without positions: length x exposure, the 3 m corner first
    (corner,) = _edges(mesh, max_edges=1).start
    np.testing.assert_allclose(corner[:2], [3.5, 2.5])
    # for a source and a microphone by the third radiator: its eight long edges and the
    # corner (the budget by length and exposure alone keeps the other radiators' long edges
    # before its 0.6 m ones)
    lo, size = RADIATORS[2]
    lo, hi = np.array(lo), np.array(lo) + size
    near = 0.5 * (lo + hi) + [[0.6, 0.0, 0.4], [0.8, 0.3, 0.2]]

    def by_radiator(edges) -> int:
        mids = 0.5 * (edges.start + edges.end)
        inside = np.all((mids >= lo - 1e-9) & (mids <= hi + 1e-9), axis=1)
        return int(np.count_nonzero(inside & (edges.length_m > 0.5)))

    kept = _edges(mesh, max_edges=9, near_m=near)
    assert kept.n_found == REAL_EDGES and kept.near_points == 2
    assert by_radiator(kept) == 8 and by_radiator(_edges(mesh, max_edges=9)) < 8
    assert any(np.allclose(s[:2], [3.5, 2.5]) for s in kept.start)
    assert np.all(np.diff(kept.importance) <= 0)
    choice = kept.choice().to_dict()
    assert (choice["found"], choice["kept"], choice["near_points"]) == (REAL_EDGES, 9, 2)
    assert "distance to the nearest of 2 source and receiver positions" in choice["rule"]


def _diffraction(scene: ss.Scene):
    from sonicspec.acoustics import engine

    settings = ss.RirSettings(rays=500, image_source_order=1, diffraction=True,
                              diffraction_max_edges=20).simulation_settings()
    traced = engine.acoustic_scene(scene.mesh, scene.library, settings)
    near = np.array([SOURCE, MIC])
    edges = engine.scene_edges(traced, settings.diffraction_max_edges, near)
    (arrivals,) = engine.diffraction_arrivals(traced, np.array(MIC), np.array([SOURCE]),
                                              settings)
    order = np.lexsort((arrivals.amplitudes[:, 0], arrivals.times_s))
    return edges, arrivals.times_s[order], arrivals.amplitudes[order]


def _sorted_segments(edges) -> np.ndarray:
    ends = np.sort(np.stack([edges.start, edges.end], axis=1), axis=1)  # each end pair sorted
    flat = ends.reshape(len(edges), 6).round(9)
    return flat[np.lexsort(flat.T[::-1])]


def test_diffracted_paths_do_not_change_when_the_objects_are_merged(obj_files) -> None:
    one = {label: SAME for label in MATERIALS}
    split = ss.Scene.from_file(obj_files["split"], materials=one, up_axis="z")
    merged = ss.Scene.from_file(obj_files["merged"], materials={"room": SAME}, up_axis="z")
    assert merged.mesh.labels == ("room",)
    edges_split, t_split, a_split = _diffraction(split)
    edges_merged, t_merged, a_merged = _diffraction(merged)
    assert len(edges_split) == 20 and edges_split.n_found == REAL_EDGES
    np.testing.assert_allclose(_sorted_segments(edges_split), _sorted_segments(edges_merged),
                               atol=1e-9)
    assert len(t_split) > 0
    np.testing.assert_allclose(t_split, t_merged, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a_split, a_merged, rtol=1e-9, atol=1e-15)
    # the edges are the geometry's, whatever the materials (flat areas are merged up to the
    # material boundaries before the edges are found)
    edges_materials, _, _ = _diffraction(
        ss.Scene.from_file(obj_files["split"], materials=_materials(), up_axis="z"))
    np.testing.assert_allclose(_sorted_segments(edges_materials),
                               _sorted_segments(edges_merged), atol=1e-9)
    # and the RIR facts say how the edges were chosen
    result = ss.compute_rir(split, SOURCE, MIC, ss.RirSettings(
        rays=500, image_source_order=1, diffraction=True, diffraction_max_edges=20), seed=0)
    assert result.diffraction_edges.found == REAL_EDGES
    assert result.diffraction_edges.kept == 20 and result.diffraction_edges.near_points == 2
    assert result.to_dict()["diffraction_edges"] == result.diffraction_edges.to_dict()


def test_a_glb_with_one_mesh_per_material_loads_closed(obj_files, tmp_path) -> None:
    import trimesh

    glb = trimesh.Scene()
    for name, tris in room_objects().items():
        points = np.array(tris, dtype=np.float64).reshape(-1, 3)
        faces = np.arange(len(points)).reshape(-1, 3)  # every triangle its own vertices
        glb.add_geometry(trimesh.Trimesh(points, faces, process=False), geom_name=name,
                         node_name=name)
    path = tmp_path / "room.glb"
    path.write_bytes(glb.export(file_type="glb"))
    scene = ss.Scene.from_file(path, materials=_materials(), up_axis="z")
    stats = mesh_stats(scene.mesh.faces, len(scene.mesh.vertices))
    assert stats.boundary_edges == 0 and stats.non_manifold_edges == 0
    assert set(scene.labels) == set(MATERIALS)
    assert scene.weld.open_edges_before > 0 and scene.weld.open_edges_after == 0
    assert leak_test(scene.mesh, np.random.default_rng(1), 5000).leak_fraction == 0.0
    found = _edges(scene.mesh)
    assert found.n_found == REAL_EDGES and found.seams == 0
    obj = ss.Scene.from_file(obj_files["split"], materials=_materials(), up_axis="z")
    assert scene.mesh.air_volume() == pytest.approx(obj.mesh.air_volume(), abs=1e-5)
    np.testing.assert_allclose(_sorted_segments(found), _sorted_segments(_edges(obj.mesh)),
                               atol=1e-6)  # glb stores float32


def test_weld_distance_is_checked(obj_files) -> None:
    mesh = load_mesh(obj_files["split"], up_axis="z", weld_distance_m=0.0)
    with pytest.raises(GeometryError, match=r"weld_distance_m: expected a finite distance "
                                            r">= 0 in metres, got -1"):
        weld_seams(mesh, -1.0)
    with pytest.raises(GeometryError, match="weld_distance_m: expected a finite distance"):
        ss.Scene.from_file(obj_files["split"], materials=_materials(), up_axis="z",
                           weld_distance_m=float("nan"))


def test_scene_inspect_reports_the_weld_the_leak_test_and_the_edges(obj_files, capsys) -> None:
    import json

    from sonicspec.cli import main

    folder = obj_files["split"].parent
    labels = ", ".join(f"{k}: {v}" for k, v in _materials().items())
    spec = folder / "s.yaml"
    base = (
        "sonicspec: 1\nname: exported\n"
        "scenes: [{kind: mesh, id: room, path: room.obj, up_axis: z, "
        f"label_materials: {{{labels}}}WELD}}]\n"
        "acoustics: {diffraction: true, diffraction_max_edges: 16}\n"
        "mixture: {speakers: 1, duration_s: 10, utterances_per_speaker: [1, 1], tasks: []}\n"
        "placement: {source_start_distance_m: [1, 2], source_end_distance_m: [1, 2],"
        " source_travel_distance_m: [0.5, 1.5]}\n"
        "corpora: {speech: {kind: generated}}\nsplits: {train: {groups: 1, scenes: [room]}}\n")
    spec.write_text(base.replace("WELD", ""))
    assert main(["scene", "inspect", str(spec), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["weld"] == {"distance_m": 1e-4, "merged_vertices": 16,
                             "t_junctions_stitched": 12, "collapsed_faces": 0,
                             "open_edges_before": 44, "open_edges_after": 0}
    assert facts["repair"]["after"]["watertight"] is True
    assert facts["leak"]["fraction"] == 0.0 and facts["leak"]["origins"] == "navigable"
    edges = facts["diffraction_edges"]
    assert (edges["found"], edges["kept"], edges["seams_left_out"]) == (REAL_EDGES, 16, 0)
    assert main(["scene", "inspect", str(spec)]) == 0
    text = capsys.readouterr().out
    assert "seams welded on load (weld_distance_m 0.0001 m): 16 vertices joined" in text
    assert f"diffraction: 16 of {REAL_EDGES} edges kept" in text
    # a tolerance of 0 keeps the file's seams for the repair to find
    spec.write_text(base.replace("WELD", ", weld_distance_m: 0"))
    assert main(["scene", "inspect", str(spec), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["weld"]["merged_vertices"] == 0 and facts["weld"]["open_edges_after"] == 44
    assert facts["repair"]["merged_vertices"] > 0
