"""Placement rules for microphone, sources and static noise/music (DESIGN.md §4)."""

from __future__ import annotations

from pydantic import Field

from sonicspec.spec.base import SpecModel, value_range, vector

DistanceRange = value_range(ge=0)
HeightRange = value_range(gt=0)


class PlacementSpec(SpecModel):
    """Where things go in a scene; every distance is measured in 3-D, metres."""

    source_start_distance_m: DistanceRange = Field(
        (1.0, 8.0), description="Distance of each speech source's start point from the mic, metres."
    )
    source_end_distance_m: DistanceRange = Field(
        (1.0, 8.0), description="Distance of each moving source's end point from the mic, metres."
    )
    source_travel_distance_m: DistanceRange = Field(
        (1.0, 8.0), description="Distance of each moving source's end point from its start, metres."
    )
    noise_distance_m: DistanceRange = Field(
        (1.0, 8.0), description="Distance of the static noise source from the mic, metres."
    )
    music_distance_m: DistanceRange = Field(
        (1.0, 8.0), description="Distance of the static music source from the mic, metres."
    )
    min_source_separation_m: float = Field(
        0.5, ge=0, description="Smallest distance between any two sources' start points, metres."
    )
    min_path_distance_m: float = Field(
        0.5,
        ge=0,
        description="Smallest distance between the microphone and any point of a moving "
        "source's path, metres (the distance ranges bound only a path's start and end; a "
        "shortest path between them can pass right by the microphone). A moving microphone: "
        "from where it starts; the rir step refuses a source within 0.1 m of it at any time.",
    )
    same_floor: bool = Field(
        True, description="Keep mic and all sources on one floor (level) of the building."
    )
    wall_clearance_m: float = Field(
        0.3, ge=0, description="Smallest horizontal distance of any position from a wall, metres."
    )
    obstacle_clearance_m: float = Field(
        0.2,
        ge=0,
        description="Smallest horizontal distance of any position from an obstacle, metres.",
    )
    source_height_m: HeightRange = Field(
        (1.5, 1.8), description="Height of speech sources (mouth) above the floor, metres."
    )
    noise_height_m: HeightRange = Field(
        (0.3, 1.8), description="Height of the noise and music sources above the floor, metres."
    )
    mic_position_m: vector(3) | None = Field(  # type: ignore[valid-type]
        None, description="Fixed microphone position [x, y, z], metres (null: sampled)."
    )
    max_tries: int = Field(
        2000,
        ge=1,
        le=10_000_000,
        description="Draws per group before placement gives up with an error naming the "
        "constraint.",
    )
    walker_radius_m: float = Field(
        0.25, gt=0, description="Radius of a walking person, for the walkable area, metres."
    )
    walker_height_m: float = Field(
        1.8, gt=0, description="Head-room a walking person needs above the floor, metres."
    )
