"""Scene import: glb/gltf/ply/obj and Matterport3D, on fixtures written in the real formats."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.errors import GeometryError, SonicspecWarning
from sonicspec.geometry.io import load_matterport, load_mesh, mpcat40_table, read_house
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.testing.meshes import write_matterport_scene, write_plain_meshes


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    return write_plain_meshes(tmp_path_factory.mktemp("plain"))


@pytest.fixture(scope="module")
def mp3d(tmp_path_factory):
    return write_matterport_scene(tmp_path_factory.mktemp("mp3d"), scene_id="fixtureScan")


def triangle_set(mesh: SceneMesh, decimals: int = 5) -> set:
    """Triangles as coordinate tuples, each rotated to start at its smallest corner.

    Rotation keeps the winding, so equal sets mean equal surfaces with equal orientation,
    whatever the vertex numbering.
    """
    out = set()
    for tri in np.round(mesh.vertices[mesh.faces], decimals) + 0.0:
        corners = [tuple(v) for v in tri]
        k = corners.index(min(corners))
        out.add(tuple(corners[k:] + corners[:k]))
    return out


def labelled_triangles(mesh: SceneMesh) -> dict:
    names = np.array(mesh.labels)[mesh.face_label]
    return {name: triangle_set(mesh.subset(names == name)) for name in mesh.labels}


@pytest.mark.parametrize("kind", ["glb", "gltf", "obj"])
def test_named_geometries_become_labels_in_the_scene_frame(plain, kind):
    mesh = load_mesh(getattr(plain, kind))
    assert set(mesh.labels) == {"room", "table"}
    # Same triangles, same winding, in z-up metres: the glTF files were written y up with the
    # table placed by its node transform, so this checks the up-axis rotation and flattening.
    assert labelled_triangles(mesh) == labelled_triangles(plain.mesh)
    assert mesh.air_volume() == pytest.approx(plain.mesh.air_volume(), rel=1e-6)
    assert mesh.materials == ("default",)


def test_ply_face_properties_become_labels_and_objects(plain):
    mesh = load_mesh(plain.ply)
    # integer label property → its decimal text; object_id → face_object
    expected_names = np.array(plain.mesh.face_label).astype(str)
    np.testing.assert_array_equal(np.array(mesh.labels)[mesh.face_label], expected_names)
    np.testing.assert_array_equal(mesh.face_object, plain.mesh.face_object)
    np.testing.assert_allclose(mesh.vertices, plain.mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, plain.mesh.faces)


def test_ascii_ply_with_label_property(tmp_path):
    path = tmp_path / "tri.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
        "property int label\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2 7\n3 0 1 3 3\n"
    )
    mesh = load_mesh(path)
    assert mesh.labels == ("3", "7")
    np.testing.assert_array_equal(mesh.face_label, [1, 0])
    assert mesh.face_object is None


def test_up_axis_override_and_unit_scale(plain):
    raw = load_mesh(plain.glb, up_axis="z")  # no rotation: the file's y-up numbers as they are
    converted = load_mesh(plain.glb)
    # (x, y, z)_gltf → (x, −z, y)
    np.testing.assert_allclose(
        converted.vertices,
        np.column_stack([raw.vertices[:, 0], -raw.vertices[:, 2], raw.vertices[:, 1]]),
    )
    np.testing.assert_allclose(converted.bounds, plain.mesh.bounds, atol=1e-6)
    assert raw.bounds[1, 1] == pytest.approx(2.5)  # the room's height lies along the file's y

    in_cm = load_mesh(plain.obj, unit_scale=0.01)
    np.testing.assert_allclose(in_cm.bounds, plain.mesh.bounds * 0.01, atol=1e-9)
    assert in_cm.air_volume() == pytest.approx(plain.mesh.air_volume() * 1e-6)
    as_y_up = load_mesh(plain.obj, up_axis="y")
    np.testing.assert_allclose(as_y_up.bounds[1], [4.0, 0.0, 3.0])


def test_matterport_faces_carry_mpcat40_categories(mp3d):
    mesh = load_matterport(mp3d.glb, mp3d.semantic_ply, mp3d.house)
    names = np.array(mesh.labels)[mesh.face_label]
    expected = np.array(mp3d.mesh.labels)[mp3d.mesh.face_label]
    np.testing.assert_array_equal(names, expected)
    np.testing.assert_array_equal(mesh.face_object, mp3d.mesh.face_object)
    # z up as written (MP3D files are z up): no y-up rotation applied
    np.testing.assert_allclose(mesh.vertices, mp3d.mesh.vertices, atol=1e-6)
    np.testing.assert_allclose(mesh.bounds, [[0, 0, 0], [5, 4, 2.6]], atol=1e-6)
    # labels ordered by mpcat40 index; category-less object and id -1 are "unlabeled"
    assert mesh.labels == ("wall", "floor", "chair", "table", "ceiling", "unlabeled")
    assert set(names[mesh.face_object == 5]) == {"unlabeled"}
    assert set(names[mesh.face_object == -1]) == {"unlabeled"}
    assert set(names[mesh.face_object == 3]) == {"table"}
    normals = mesh.face_normals
    assert np.all(normals[names == "floor"] @ [0, 0, 1] > 0.99)  # floor faces up, into the air
    # materials then follow from the labels
    mapped = mesh.with_materials({"wall": "gypsum", "floor": "carpet"}, default="wood")
    material = np.array(mapped.materials)[mapped.face_material]
    assert set(material[names == "floor"]) == {"carpet"}
    assert set(material[names == "chair"]) == {"wood"}


def test_matterport_partial_inputs(mp3d):
    ids_only = load_matterport(mp3d.glb, mp3d.semantic_ply)
    assert ids_only.face_label is None
    np.testing.assert_array_equal(ids_only.face_object, mp3d.mesh.face_object)
    render = load_matterport(mp3d.glb)
    assert render.face_label is None
    assert triangle_set(render) == triangle_set(mp3d.mesh)
    with pytest.raises(GeometryError, match="expected semantic_ply_path with house_path"):
        load_matterport(mp3d.glb, house_path=mp3d.house)


def test_house_file_is_parsed(mp3d):
    house = read_house(mp3d.house)
    assert house.name == "fixtureScan"
    assert house.categories[3].raw_name == "dining table"
    assert house.categories[3].mpcat40_index == 5
    assert house.object_mpcat40(4) == "chair"
    assert house.object_mpcat40(5) == "unlabeled"
    assert house.object_mpcat40(-1) == "unlabeled"
    assert house.segment_to_object[1003] == 3
    table = {c.index: c.name for c in mpcat40_table()}
    assert len(table) == 42 and table[17] == "ceiling" and table[41] == "unlabeled"


def test_house_errors(tmp_path, mp3d):
    bad_header = tmp_path / "a.house"
    bad_header.write_text("ASCII 1.0\nH x\n")
    with pytest.raises(GeometryError, match=r"a\.house: expected a Matterport3D house file"):
        read_house(bad_header)
    malformed = tmp_path / "b.house"
    malformed.write_text("ASCII 1.1\nC 0 1 wall\n")
    with pytest.raises(GeometryError, match=r"b\.house:2: expected a well-formed 'C' line"):
        read_house(malformed)
    unknown_name = tmp_path / "c.house"
    unknown_name.write_text("ASCII 1.1\nC 0 1 wall 1 wallz 0 0 0 0 0\n")
    with pytest.raises(GeometryError, match="expected an mpcat40 category name, got 'wallz'"):
        read_house(unknown_name)
    undeclared_category = tmp_path / "d.house"
    undeclared_category.write_text("ASCII 1.1\nO 0 0 7 0 0 0 1 0 0 0 1 0 1 1 1 0 0 0 0 0 0 0 0\n")
    with pytest.raises(GeometryError, match="category 7 to be declared"):
        read_house(undeclared_category)
    # a house file of another scene: the semantic mesh's objects are not all declared
    other = tmp_path / "other.house"
    other.write_text("\n".join(mp3d.house.read_text().splitlines()[:-8]) + "\n")
    with pytest.raises(GeometryError, match=r"expected object ids declared in .*other\.house"):
        load_matterport(mp3d.glb, mp3d.semantic_ply, other)


def test_semantic_ply_without_object_ids_is_an_error(plain, mp3d, tmp_path):
    plain_ply = tmp_path / "x_semantic.ply"
    plain_ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    with pytest.raises(
        GeometryError, match=r"x_semantic\.ply: expected a face property 'object_id'"
    ):
        load_matterport(mp3d.glb, plain_ply, mp3d.house)


def test_missing_file(tmp_path):
    missing = tmp_path / "nowhere.glb"
    with pytest.raises(
        GeometryError, match=r"expected an existing file, got missing path .*nowhere\.glb"
    ):
        load_mesh(missing)
    with pytest.raises(GeometryError, match=r"nowhere\.glb"):
        load_matterport(missing)


def test_unknown_extension(tmp_path):
    path = tmp_path / "scene.fbx"
    path.write_bytes(b"\x00")
    with pytest.raises(GeometryError, match=r"expected a file ending in \.glb, .*got .*scene\.fbx"):
        load_mesh(path)


@pytest.mark.parametrize("suffix", [".glb", ".ply", ".gltf"])
def test_corrupt_file(tmp_path, suffix):
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(b"this is not a mesh \x00\x01\x02 at all")
    with pytest.raises(GeometryError, match=rf"broken\{suffix}: expected a readable"):
        load_mesh(path)


def test_truncated_glb(tmp_path, plain):
    path = tmp_path / "truncated.glb"
    path.write_bytes(plain.glb.read_bytes()[:200])
    with pytest.raises(GeometryError, match=r"truncated\.glb: expected a readable glb mesh"):
        load_mesh(path)


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
        ("empty.obj", ""),
        (
            "points.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n0 0 0\n",
        ),
    ],
)
def test_empty_mesh(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(
        GeometryError, match=rf"{name.replace('.', '[.]')}: expected a mesh with triangles"
    ):
        load_mesh(path)


def test_face_index_out_of_range_names_the_file(tmp_path):
    path = tmp_path / "badindex.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n")
    with pytest.raises(GeometryError, match=r"badindex\.obj"):
        load_mesh(path)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"up_axis": "x"}, "up_axis: expected 'auto', 'y' or 'z', got 'x'"),
        ({"unit_scale": 0.0}, "unit_scale: expected a finite positive factor"),
    ],
)
def test_bad_options(plain, kwargs, message):
    with pytest.raises(GeometryError, match=message):
        load_mesh(plain.obj, **kwargs)


def test_ply_labels_on_polygon_faces_warn(tmp_path):
    path = tmp_path / "quads.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
        "property int label\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n"
        "4 0 1 2 3 5\n3 0 1 4 9\n"
    )
    with pytest.warns(SonicspecWarning, match=r"quads\.ply: expected one label per triangle"):
        mesh = load_mesh(path)
    assert mesh.n_faces == 3 and mesh.face_label is None


def test_semantic_ply_with_polygon_faces_is_an_error(tmp_path, mp3d):
    path = tmp_path / "quads_semantic.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "property int object_id\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 0\n"
    )
    with pytest.raises(GeometryError, match=r"quads_semantic\.ply: expected one object_id per"):
        load_matterport(mp3d.glb, path)
