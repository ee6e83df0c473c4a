"""The scanned-house scenario end to end: repair, then the floor plan shows the three rooms."""

from __future__ import annotations

import numpy as np
import pytest

from sonicspec.geometry.navigation import NavigationSettings, build_navigation
from sonicspec.geometry.repair import RepairSettings, leak_test, repair_mesh
from sonicspec.testing.meshes import HOUSE_DOORS, HOUSE_ROOMS, scanned_house


@pytest.fixture(scope="module")
def repaired():
    house = scanned_house(np.random.default_rng(11))
    mesh, report = repair_mesh(house.damaged, RepairSettings(max_hole_size_m=2.0))
    return mesh, report


def test_repair_closes_the_scan(repaired) -> None:
    mesh, report = repaired
    assert report.watertight
    assert leak_test(mesh, np.random.default_rng(0), 20_000).leak_fraction == 0.0


def test_floor_plan_shows_the_rooms_joined_by_doors(repaired) -> None:
    mesh, _ = repaired
    radius = 0.25
    nav = build_navigation(mesh, NavigationSettings(cell_m=0.05, walker_radius_m=radius))
    (grid,) = nav.grids
    assert grid.floor.z_m == pytest.approx(0.0, abs=0.02)
    # Every room is walkable at its centre, and the doors join all three into one component.
    centres = np.array([[(x0 + x1) / 2, (y0 + y1) / 2] for x0, x1, y0, y1 in HOUSE_ROOMS])
    assert np.all(grid.component_at(centres) == 0)
    # Each room contributes its floor shrunk by the walker's radius; the 1 m doors add a
    # passage 0.2 m deep but narrower than 1 m by the two radii.
    rooms = sum((x1 - x0 - 2 * radius) * (y1 - y0 - 2 * radius) for x0, x1, y0, y1 in HOUSE_ROOMS)
    doors = sum(0.2 * (max(x1 - x0, y1 - y0) - 2 * radius) for x0, x1, y0, y1 in HOUSE_DOORS)
    assert grid.area_m2 == pytest.approx(rooms + doors, rel=0.05)
    # Points inside the walls between rooms are not walkable.
    wall_points = np.array([[4.1, 1.0], [4.1, 4.0], [3.0, 5.1]])
    assert np.all(grid.component_at(wall_points) == -1)


def test_a_scan_with_t_junctions_is_stitched_closed() -> None:
    """The scanned house with, on top of its other damage, 60 seam edges bisected on one side
    only: repair stitches every T-junction and the result is watertight and does not leak."""
    house = scanned_house(np.random.default_rng(11), t_junctions=60)
    assert house.n_t_junctions > 50
    settings = RepairSettings(max_hole_size_m=2.0, leak_test_rays=20_000, if_not_watertight="error")
    mesh, report = repair_mesh(house.damaged, settings, np.random.default_rng(0))
    assert report.t_junctions_stitched == house.n_t_junctions
    assert report.watertight and report.after.inconsistent_edges == 0
    assert report.holes_closed == 1  # only the missing panel is a hole
    assert report.leak.leak_fraction == 0.0
    assert mesh.air_volume() == pytest.approx(house.clean.air_volume(), rel=2e-3)
    # the T-junctions are drawn last: the rest of the damage is the plain scan's
    plain = scanned_house(np.random.default_rng(11)).damaged.vertices
    np.testing.assert_array_equal(house.damaged.vertices[: len(plain)], plain)
