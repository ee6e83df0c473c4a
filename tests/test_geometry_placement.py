"""Placement sampler: every rule of the recipe holds over many seeds; failures name the rule."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from sonicspec.errors import PlacementError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.navigation import (
    NavigationSettings,
    build_navigation,
    resample_polyline,
)
from sonicspec.geometry.placement import (
    PlacementSettings,
    polyline_distance,
    sample_placement,
)
from sonicspec.geometry.procedural import add_obstacles, box_obstacle, shoebox

NAV = NavigationSettings(cell_m=0.05, walker_radius_m=0.25)
ROOM = (10.0, 7.0, 3.0)
BOX_CENTER, BOX_SIZE = np.array([5.0, 2.5]), np.array([1.2, 2.0])  # furniture, 1 m high
SEEDS = range(50)


@pytest.fixture(scope="module")
def hall():
    room = add_obstacles(shoebox(ROOM), [box_obstacle([*BOX_CENTER, 0.5], [*BOX_SIZE, 1.0])])
    return build_navigation(room, NAV)


@pytest.fixture(scope="module")
def house():
    """Two storeys of 8 × 6 m: floors at z = 0 and z = 3.2."""
    upper = shoebox([8, 6, 2.8])
    upper = upper.replace(vertices=upper.vertices + np.array([0, 0, 3.2]))
    return build_navigation(SceneMesh.concatenate([shoebox([8, 6, 3]), upper]), NAV)


def wall_distance(points):
    x, y = points[..., 0], points[..., 1]
    return np.minimum.reduce([x, ROOM[0] - x, y, ROOM[1] - y])


def box_distance(points):
    d = np.maximum(np.abs(points[..., :2] - BOX_CENTER) - BOX_SIZE / 2, 0.0)
    return np.hypot(d[..., 0], d[..., 1])


def in_range(value, bounds, tol=1e-9):
    return bounds[0] - tol <= value <= bounds[1] + tol


def test_every_rule_holds_over_many_seeds(hall):
    # Clearances above the walker radius (0.25 m), so they bind beyond walkability.
    settings = PlacementSettings(wall_clearance_m=0.5, obstacle_clearance_m=0.6)
    grid = hall.grid(0)
    motions = ["shortest_path", "line", "static"]
    lengths_over_straight = []
    for seed in SEEDS:
        p = sample_placement(
            hall,
            settings,
            scene_id="hall",
            speech=motions,
            noise=True,
            music=True,
            rng=np.random.default_rng(seed),
        )
        assert p.scene_id == "hall" and p.floor_index == 0
        assert p.mic_m[2] == pytest.approx(settings.mic_height_m)
        statics = [p.noise, p.music]
        everything = [p.mic_m] + [s.start_m for s in p.speech] + [s.end_m for s in p.speech]
        everything += [s.start_m for s in statics]
        everything = np.array(everything)
        # Clearances, measured on the analytic room and box (the sampler only knows the grid).
        assert wall_distance(everything).min() >= settings.wall_clearance_m - 0.005
        assert box_distance(everything).min() >= settings.obstacle_clearance_m - 0.005
        for source, motion in zip(p.speech, motions, strict=True):
            assert source.motion == motion
            assert in_range(source.height_m, settings.source_height_m)
            assert source.start_m[2] == pytest.approx(source.height_m)
            assert source.end_m[2] == pytest.approx(source.height_m)
            d_start = np.linalg.norm(source.start_m - p.mic_m)
            assert in_range(d_start, settings.source_start_distance_m)
            if motion == "static":
                assert np.array_equal(source.end_m, source.start_m)
                assert source.path_m.shape == (1, 3) and source.path_length_m == 0.0
                continue
            assert in_range(np.linalg.norm(source.end_m - p.mic_m), settings.source_end_distance_m)
            travel = np.linalg.norm(source.end_m - source.start_m)
            assert in_range(travel, settings.source_travel_distance_m)
            assert np.array_equal(source.path_m[0], source.start_m)
            assert np.array_equal(source.path_m[-1], source.end_m)
            steps = np.linalg.norm(np.diff(source.path_m, axis=0), axis=1)
            assert source.path_length_m == pytest.approx(steps.sum())
            assert source.path_length_m >= travel - 1e-9
            # The walked path keeps the walker's radius from walls and box (within a cell).
            dense = resample_polyline(source.path_m, 0.02)
            assert wall_distance(dense).min() >= NAV.walker_radius_m - NAV.cell_m
            assert box_distance(dense).min() >= NAV.walker_radius_m - NAV.cell_m
            # Its vertices lie on the mic's walkable component (segments may graze cell corners).
            assert np.all(grid.component_at(source.path_m) == grid.component_at(p.mic_m))
            # Issue 18: the whole path keeps its distance from the mic, not only its ends.
            assert np.linalg.norm(dense - p.mic_m, axis=1).min() >= (
                settings.min_path_distance_m - 1e-6)
            if motion == "line":
                assert source.path_length_m == pytest.approx(travel)
                assert grid.line_of_sight(source.start_m, source.end_m)
            else:
                lengths_over_straight.append(source.path_length_m / travel)
        for source, bounds in (
            (p.noise, settings.noise_distance_m),
            (p.music, settings.music_distance_m),
        ):
            assert source.motion == "static"
            assert in_range(np.linalg.norm(source.start_m - p.mic_m), bounds)
            assert in_range(source.height_m, settings.noise_height_m)
        positions = [s.start_m for s in (*p.speech, p.noise, p.music)]
        for a, b in itertools.combinations(positions, 2):
            assert np.linalg.norm(a - b) >= settings.min_source_separation_m
    # The box sits in the middle of the hall: some shortest paths had to walk round it.
    assert max(lengths_over_straight) > 1.02


def test_placement_is_deterministic_for_a_generator(hall):
    def place(seed):
        return sample_placement(
            hall,
            PlacementSettings(),
            scene_id="hall",
            speech=["shortest_path"] * 3,
            noise=True,
            music=True,
            rng=np.random.default_rng(seed),
        ).to_dict()

    first = place(123)
    assert place(123) == first
    assert place(124) != first
    # to_dict is plain JSON.
    assert json.loads(json.dumps(first)) == first
    assert len(first["speech"]) == 3 and first["noise"]["motion"] == "static"


def test_same_floor_keeps_the_storeys_apart(house):
    settings = PlacementSettings()
    mic_floors, crossed = set(), False
    for seed in range(25):
        p = sample_placement(
            house,
            settings,
            scene_id="house",
            speech=["shortest_path", "static"],
            noise=True,
            music=True,
            rng=np.random.default_rng(seed),
        )
        mic_floors.add(p.floor_index)
        z_floor = house.floors[p.floor_index].z_m
        assert p.mic_m[2] == pytest.approx(z_floor + settings.mic_height_m)
        for source in (*p.speech, p.noise, p.music):
            assert source.floor_index == p.floor_index
            assert np.all(source.path_m[:, 2] - z_floor == pytest.approx(source.height_m))
    # Both storeys host groups, so the rule was exercised on each.
    assert mic_floors == {0, 1}

    loose = PlacementSettings(same_floor=False)
    for seed in range(25):
        p = sample_placement(
            house,
            loose,
            scene_id="house",
            speech=["shortest_path", "static"],
            noise=True,
            music=True,
            rng=np.random.default_rng(seed),
        )
        floors = {s.floor_index for s in (*p.speech, p.noise, p.music)}
        crossed |= floors != {p.floor_index}
        # Distances still hold in 3-D across storeys, and a path never changes floor.
        for source in (*p.speech, p.noise, p.music):
            assert in_range(np.linalg.norm(source.start_m - p.mic_m), (1.0, 8.0))
            z = house.floors[source.floor_index].z_m + source.height_m
            assert source.path_m[:, 2] == pytest.approx(np.full(len(source.path_m), z))
    assert crossed  # without the rule, sources do land on the other storey


def test_fixed_microphone_is_used(hall):
    settings = PlacementSettings(mic_position_m=(2.0, 5.0, 1.2))
    p = sample_placement(
        hall,
        settings,
        scene_id="hall",
        speech=["line"],
        noise=False,
        music=False,
        rng=np.random.default_rng(0),
    )
    assert p.mic_m.tolist() == [2.0, 5.0, 1.2]
    assert p.noise is None and p.music is None
    assert in_range(np.linalg.norm(p.speech[0].start_m - p.mic_m), (1.0, 8.0))


def test_fixed_microphone_off_the_floor_is_an_error(hall):
    for position in ((20.0, 5.0, 1.5), (2.0, 5.0, 2.5)):  # outside; above head height
        with pytest.raises(PlacementError, match=r"scene 'hall': mic_position_m: expected a point"):
            sample_placement(
                hall,
                PlacementSettings(mic_position_m=position),
                scene_id="hall",
                speech=["static"],
                noise=False,
                music=False,
                rng=np.random.default_rng(0),
            )


def test_impossible_distance_in_a_small_room_names_scene_and_rule():
    closet = build_navigation(shoebox([1.0, 1.0, 2.5]), NavigationSettings(min_floor_area_m2=0.1))
    with pytest.raises(
        PlacementError,
        match=r"scene 'closet': could not place speech source 0's start point on floor 0: "
        r"expected .* within 300 tries.*most failed: distance from the mic 1–8 m",
    ):
        sample_placement(
            closet,
            PlacementSettings(max_tries=300),
            scene_id="closet",
            speech=["line"],
            noise=True,
            music=False,
            rng=np.random.default_rng(0),
        )


def test_out_of_reach_range_names_the_rule(hall):
    settings = PlacementSettings(noise_distance_m=(15.0, 20.0), max_tries=500)
    with pytest.raises(
        PlacementError,
        match=r"scene 'hall': could not place the noise source on floor 0.*"
        r"most failed: distance from the mic 15–20 m",
    ):
        sample_placement(
            hall,
            settings,
            scene_id="hall",
            speech=["static"],
            noise=True,
            music=False,
            rng=np.random.default_rng(0),
        )


def test_travel_range_failure_names_the_end_point(hall):
    settings = PlacementSettings(source_travel_distance_m=(11.0, 12.0), max_tries=400)
    with pytest.raises(
        PlacementError,
        match=r"speech source 0's end point on floor 0.*most failed: distance from the (mic|start)",
    ):
        sample_placement(
            hall,
            settings,
            scene_id="hall",
            speech=["shortest_path"],
            noise=False,
            music=False,
            rng=np.random.default_rng(0),
        )


def test_clearance_larger_than_the_room_is_an_error(hall):
    with pytest.raises(
        PlacementError,
        match=r"scene 'hall': expected walkable area with wall "
        r"clearance >= 4 m",
    ):
        sample_placement(
            hall,
            PlacementSettings(wall_clearance_m=4.0),
            scene_id="hall",
            speech=["static"],
            noise=False,
            music=False,
            rng=np.random.default_rng(0),
        )


def test_unknown_motion_is_an_error(hall):
    with pytest.raises(PlacementError, match=r"speech\[1\]: expected one of .*got 'run'"):
        sample_placement(
            hall,
            PlacementSettings(),
            scene_id="hall",
            speech=["static", "run"],
            noise=False,
            music=False,
            rng=np.random.default_rng(0),
        )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"source_start_distance_m": (8.0, 1.0)}, r"source_start_distance_m: expected finite"),
        (
            {"noise_height_m": (0.0, 1.0)},
            r"noise_height_m: expected finite \[min, max\] with min > 0",
        ),
        ({"music_distance_m": 3.0}, r"music_distance_m: expected a pair"),
        ({"wall_clearance_m": -0.1}, r"wall_clearance_m: expected a finite distance >= 0"),
        ({"mic_height_m": 0.0}, r"mic_height_m: expected a finite positive"),
        ({"max_tries": 0}, r"max_tries: expected an integer >= 1"),
        ({"item_budget": 2.5}, r"item_budget: expected an integer >= 1"),
        ({"mic_position_m": (1.0, 2.0)}, r"mic_position_m: expected \[x, y, z\]"),
    ],
)
def test_settings_errors(kwargs, match):
    with pytest.raises(PlacementError, match=match):
        PlacementSettings(**kwargs)


def test_navigation_settings_follow_the_walker():
    nav = PlacementSettings(walker_radius_m=0.3, walker_height_m=1.9).navigation_settings(0.1)
    assert (nav.cell_m, nav.walker_radius_m, nav.walker_height_m) == (0.1, 0.3, 1.9)


def test_a_mic_in_a_closet_is_redrawn():
    # A 7 × 5 m room and a separate 2.5 × 2.5 m closet (12 % of the eligible area): no source
    # can be 3–8 m from a mic drawn in the closet within its component, so such groups
    # restart from a new mic, and every placement ends up in the room.
    closet = shoebox([2.5, 2.5, 2.5])
    closet = closet.replace(vertices=closet.vertices + np.array([8.0, 0.0, 0.0]))
    nav = build_navigation(SceneMesh.concatenate([shoebox([7, 5, 3]), closet]), NAV)
    assert nav.grid(0).n_components == 2
    settings = PlacementSettings(
        source_start_distance_m=(3.0, 8.0), noise_distance_m=(3.0, 8.0), item_budget=20
    )
    restarts = 0
    for seed in range(60):
        p = sample_placement(
            nav,
            settings,
            scene_id="flat",
            speech=["shortest_path"],
            noise=True,
            music=False,
            rng=np.random.default_rng(seed),
        )
        assert p.mic_m[0] < 7 and p.speech[0].start_m[0] < 7 and p.noise.start_m[0] < 7
        restarts += p.restarts
    assert restarts >= 1


def test_separation_failure_names_the_rule(hall):
    settings = PlacementSettings(min_source_separation_m=20.0, max_tries=300)
    with pytest.raises(
        PlacementError,
        match=r"speech source 1's start point.*most failed: separation from other sources "
        r">= 20 m",
    ):
        sample_placement(
            hall,
            settings,
            scene_id="hall",
            speech=["static", "static"],
            noise=False,
            music=False,
            rng=np.random.default_rng(0),
        )


def test_unsmoothed_paths_follow_the_grid(hall):
    def place(smooth):
        return sample_placement(
            hall,
            PlacementSettings(smooth_paths=smooth),
            scene_id="hall",
            speech=["shortest_path"],
            noise=False,
            music=False,
            rng=np.random.default_rng(5),
        ).speech[0]

    smooth, raw = place(True), place(False)
    assert np.array_equal(smooth.start_m, raw.start_m) and np.array_equal(smooth.end_m, raw.end_m)
    assert raw.path_length_m >= smooth.path_length_m
    assert len(raw.path_m) > len(smooth.path_m)
    # Interior vertices of the grid path are cell centres, one cell (or a diagonal) apart.
    steps = np.linalg.norm(np.diff(raw.path_m[1:-1, :2], axis=0), axis=1)
    assert np.all(np.isclose(steps, 0.05) | np.isclose(steps, 0.05 * np.sqrt(2)))



def test_paths_keep_their_distance_from_the_mic_and_the_rule_is_needed(hall):
    """Issue 18: a path drawn between ends 1-8 m from the mic can pass 0.2 m from it; with
    min_path_distance_m (default 0.5 m) every path keeps its distance all along."""
    def closest(settings, seed):
        p = sample_placement(hall, settings, scene_id="hall", speech=["line"] * 3,
                             noise=False, music=False, rng=np.random.default_rng(seed))
        return min(polyline_distance(s.path_m, p.mic_m) for s in p.speech)

    unruled = [closest(PlacementSettings(min_path_distance_m=0.0), seed) for seed in SEEDS]
    assert min(unruled) < 0.5  # without the rule some walk passes close by
    ruled = [closest(PlacementSettings(), seed) for seed in range(20)]
    assert min(ruled) >= 0.5 - 1e-9
    with pytest.raises(PlacementError, match=r"end point .*most failed: a path closer than "
                       r"8\.5 m to the mic"):
        sample_placement(hall, PlacementSettings(min_path_distance_m=8.5, max_tries=300),
                         scene_id="hall", speech=["shortest_path"], noise=False, music=False,
                         rng=np.random.default_rng(0))


def test_polyline_distance():
    path = np.array([[0.0, 0, 0], [4, 0, 0], [4, 3, 0]])
    assert polyline_distance(path, [2, 1, 0]) == pytest.approx(1.0)
    assert polyline_distance(path, [5, 1.5, 0]) == pytest.approx(1.0)
    assert polyline_distance(path, [-3, 4, 0]) == pytest.approx(5.0)
    assert polyline_distance(path[:1], [0, 0, 2]) == pytest.approx(2.0)


def test_polylines_distance_is_exact_against_dense_sampling() -> None:
    from sonicspec.geometry.placement import polylines_distance

    rng = np.random.default_rng(5)
    for _ in range(20):
        a, b = rng.uniform(0, 5, (4, 3)), rng.uniform(0, 5, (3, 3))
        t = np.linspace(0, 1, 801)[:, None]
        dense = [np.concatenate([p + t * (q - p) for p, q in itertools.pairwise(x)])
                 for x in (a, b)]
        brute = min(np.linalg.norm(dense[0] - y, axis=1).min() for y in dense[1])
        assert polylines_distance(a, b) <= brute + 1e-12
        assert polylines_distance(a, b) == pytest.approx(brute, abs=5e-3)
    crossing = polylines_distance(np.array([[0, 0, 0], [2, 0, 0.0]]),
                                  np.array([[1, -1, 0.5], [1, 1, 0.5]]))
    assert crossing == pytest.approx(0.5, abs=1e-12)  # the interior closest points


def test_sources_keep_their_distance_from_a_moving_microphones_whole_walk(hall) -> None:
    """Issue 28 item 11: placement drew sources around the walk's start only; one came
    within 0.05 m of the walking microphone and the rir job refused it. Every source and
    every path now keeps min_path_distance_m from the whole walk."""
    from sonicspec.geometry.placement import polylines_distance

    walk = ((1.0, 5.5, 1.5), (8.5, 5.5, 1.5), (8.5, 1.0, 1.5))
    rules = dict(mic_position_m=walk[0], min_path_distance_m=0.6)
    closest_before, closest_now = [], []
    for seed in SEEDS:
        for with_walk, out in ((False, closest_before), (True, closest_now)):
            settings = PlacementSettings(**rules, mic_path_m=walk if with_walk else None)
            p = sample_placement(hall, settings, scene_id="hall",
                                 speech=["shortest_path", "line", "static"], noise=True,
                                 music=True, rng=np.random.default_rng(seed))
            gaps = [polylines_distance(s.path_m, np.asarray(walk)) for s in p.speech]
            gaps += [polyline_distance(np.asarray(walk), s.start_m)
                     for s in (p.noise, p.music)]
            out.append(min(gaps))
    assert min(closest_before) < 0.6  # the fault: the walk was not looked at
    assert min(closest_now) >= 0.6 - 1e-9
