"""Direct sound: delay r/c, 1/(4πr), transmission through walls, occlusion in an L-shaped room."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.acoustics.paths.direct import direct_sound
from sonicspec.acoustics.room.scene import AcousticScene
from sonicspec.errors import AcousticsError
from sonicspec.testing.rooms import extruded_room, partitioned_shoebox, shoebox, uniform_scene

FS_HZ = 16_000
C = 343.0


def test_mesh_helper_normals_point_into_the_room():
    verts, faces = shoebox(4, 3, 2.5)
    scene = uniform_scene(verts, faces)
    centre = np.array([2, 1.5, 1.25])
    tri_centre = verts[faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", scene.normals, centre - tri_centre) > 0)


@pytest.mark.parametrize("pos", [[1.0, 1.0, 1.2], [3.7, 2.1, 0.4], [0.3, 2.8, 2.2]])
def test_direct_sound_delay_and_amplitude(pos):
    verts, faces = shoebox(4, 3, 2.5)
    scene = uniform_scene(verts, faces)
    src = np.array([2.2, 0.9, 1.6])
    (arr,) = direct_sound(scene, src, np.array([pos]))
    r = np.linalg.norm(src - pos)
    assert len(arr) == 1
    # within ±1 sample of r/c (it is in fact exact: fractional, never rounded)
    assert abs(arr.times_s[0] * FS_HZ - r / C * FS_HZ) <= 1.0
    assert arr.times_s[0] == pytest.approx(r / C, rel=1e-12)
    level_db = 20 * np.log10(arr.amplitudes[0] * 4 * np.pi * r)
    assert np.all(np.abs(level_db) < 0.2)
    # direction of arrival points from the receiver to the source
    np.testing.assert_allclose(arr.directions[0], (src - pos) / r, atol=1e-12)


def test_air_absorption_is_half_the_energy_exponent_in_amplitude():
    verts, faces = shoebox(4, 3, 2.5)
    scene = uniform_scene(verts, faces, n_bands=2)
    src, rcv = np.array([0.5, 0.5, 1.0]), np.array([[3.5, 2.5, 1.5]])
    air = np.array([0.0, 0.01])
    (arr,) = direct_sound(scene, src, rcv, air_m_per_band=air)
    r = np.linalg.norm(src - rcv[0])
    np.testing.assert_allclose(arr.amplitudes[0], np.exp(-0.5 * air * r) / (4 * np.pi * r))


def room_with_partition(tau):
    """6 x 4 x 3 m shoebox split at x = 3 by a single-sheet partition of transmission tau."""
    verts, faces = partitioned_shoebox(6, 4, 3, 3)
    n_bands = 3
    f = len(faces)
    tr = np.zeros((f, n_bands))
    tr[-2:] = tau
    return AcousticScene(verts, faces, np.full((f, n_bands), 0.2), np.zeros((f, n_bands)), tr)


def test_wall_with_tau_001_lowers_direct_sound_by_20_db():
    src = np.array([1.0, 1.3, 1.5])
    rcv = np.array([[5.0, 2.9, 1.2]])
    (through,) = direct_sound(room_with_partition(0.01), src, rcv)
    r = np.linalg.norm(src - rcv[0])
    drop_db = 20 * np.log10(through.amplitudes[0] * 4 * np.pi * r)
    assert np.all(np.abs(drop_db + 20.0) <= 1.0)
    (opaque,) = direct_sound(room_with_partition(0.0), src, rcv)
    assert len(opaque) == 0


def l_room():
    poly = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    tris = [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)]  # fan from the reflex corner
    return extruded_room(poly, tris, 3.0)


def test_l_shaped_room_without_line_of_sight_has_no_direct_sound():
    verts, faces = l_room()
    scene = uniform_scene(verts, faces)
    src = np.array([5.5, 1.0, 1.5])  # east arm
    rcvs = np.array([[1.0, 5.5, 1.5], [1.0, 1.0, 1.5]])  # north arm (hidden), corner (visible)
    hidden, visible = direct_sound(scene, src, rcvs)
    assert len(hidden) == 0
    assert len(visible) == 1


def test_direct_sound_errors():
    verts, faces = shoebox(4, 3, 2.5)
    scene = uniform_scene(verts, faces, n_bands=2)
    with pytest.raises(AcousticsError, match="receivers: expected positions distinct"):
        direct_sound(scene, np.array([1.0, 1, 1]), np.array([[1.0, 1, 1]]))
    with pytest.raises(AcousticsError, match="air_m_per_band: expected 2 finite"):
        direct_sound(scene, np.array([1.0, 1, 1]), np.array([[2.0, 1, 1]]), air_m_per_band=[0.1])
    with pytest.raises(AcousticsError, match="source: expected one position"):
        direct_sound(scene, np.ones((2, 3)), np.array([[2.0, 1, 1]]))
    with pytest.raises(AcousticsError, match="receivers: expected finite positions"):
        direct_sound(scene, np.array([1.0, 1, 1]), np.ones((2, 2)))
    with pytest.raises(AcousticsError, match="speed_of_sound_m_s: expected > 0"):
        direct_sound(scene, np.array([1.0, 1, 1]), np.array([[2.0, 1, 1]]), speed_of_sound_m_s=0)


def test_scene_errors():
    verts, faces = shoebox(4, 3, 2.5)
    f = len(faces)
    ok = np.zeros((f, 2))
    with pytest.raises(AcousticsError, match=r"absorption: expected coefficients in \[0, 1\]"):
        AcousticScene(verts, faces, np.full((f, 2), 1.5), ok, ok)
    with pytest.raises(AcousticsError, match="scattering: expected an array of shape"):
        AcousticScene(verts, faces, ok, np.zeros((f + 1, 2)), ok)
    with pytest.raises(AcousticsError, match="expected the same number of bands"):
        AcousticScene(verts, faces, ok, np.zeros((f, 3)), ok)
    with pytest.raises(AcousticsError, match="faces: expected indices in"):
        AcousticScene(verts, faces + 100, ok, ok, ok)
    with pytest.raises(AcousticsError, match="faces: expected non-degenerate"):
        bad = faces.copy()
        bad[0] = [0, 0, 1]
        AcousticScene(verts, bad, ok, ok, ok)
    with pytest.raises(AcousticsError, match="faces: expected integer"):
        AcousticScene(verts, faces.astype(float), ok, ok, ok)
    with pytest.raises(AcousticsError, match="vertices: expected shape"):
        AcousticScene(verts[:, :2], faces, ok, ok, ok)
    with pytest.raises(AcousticsError, match="vertices: expected finite"):
        v = verts.copy()
        v[0, 0] = np.nan
        AcousticScene(v, faces, ok, ok, ok)
    with pytest.raises(AcousticsError, match="faces: expected shape"):
        AcousticScene(verts, faces[:, :2], ok, ok, ok)


def test_crossings_count_every_surface_between_points():
    scene = room_with_partition(0.5)
    seg, face = scene.crossings(
        np.array([[1.0, 2, 1.5], [1.0, 2, 1.5]]), np.array([[5.0, 2, 1.5], [2.0, 2, 1.5]])
    )
    assert seg.tolist() == [0]
    assert set(face.tolist()) <= {scene.n_faces - 2, scene.n_faces - 1}
    # from outside the room through two walls and the partition
    seg, _ = scene.crossings(np.array([[-1.0, 2, 1.5]]), np.array([[7.0, 2, 1.5]]))
    assert len(seg) == 3
    np.testing.assert_allclose(
        scene.segment_transmission(np.array([[1.0, 2, 1.5]]), np.array([[5.0, 2, 1.5]])), 0.5
    )
