"""Trajectories: how sources (and optionally the microphone) move during a clip."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from sonicspec.spec.base import SpecModel, vector

Vec3 = vector(3)


class StaticTrajectorySpec(SpecModel):
    """The source stays at its start position (one RIR)."""

    kind: Literal["static"] = Field(description="Trajectory type.")


class _MovingBase(SpecModel):
    rir_spacing_m: float = Field(
        0.25,
        gt=0,
        le=5.0,
        description="Distance between RIR points along the path, metres. The crossfade "
        "between neighbouring RIRs comb-filters the direct sound at any spacing (measured in "
        "bench/bench_motion.py, speech: worst smoothed dip -25 dB at 0.25 m, -17 dB at 0.05 m).",
    )
    speed_m_s: float | None = Field(
        None,
        gt=0,
        le=10.0,
        description="Walking speed, m/s; null sets it so the path spans `span`.",
    )
    span: Literal["speech", "clip"] = Field(
        "speech",
        description="What the walk spans when speed_m_s is null: the source's speech (from "
        "its first utterance to the end of its last) or the whole clip (the SonicSim paper: "
        "the speed is set so the trajectory spans the fixed duration T). With a speed, the "
        "walk starts at the start of this span.",
    )


class LineTrajectorySpec(_MovingBase):
    """A straight line from the start to the end point (placement draws them unless given)."""

    kind: Literal["line"] = Field(description="Trajectory type.")
    start_m: Vec3 | None = Field(None, description="Fixed start point, metres (null: sampled).")
    end_m: Vec3 | None = Field(None, description="Fixed end point, metres (null: sampled).")


class WaypointsTrajectorySpec(_MovingBase):
    """A polyline through fixed points."""

    kind: Literal["waypoints"] = Field(description="Trajectory type.")
    points_m: list[Vec3] = Field(min_length=2, description="Waypoints [x, y, z] in order, metres.")


class ShortestPathTrajectorySpec(_MovingBase):
    """The shortest walkable path between a sampled start and end point (the SonicSet recipe)."""

    kind: Literal["shortest_path"] = Field(description="Trajectory type.")
    smooth: bool = Field(True, description="Shorten the grid path by line-of-sight smoothing.")


TrajectorySpec = Annotated[
    StaticTrajectorySpec
    | LineTrajectorySpec
    | WaypointsTrajectorySpec
    | ShortestPathTrajectorySpec,
    Field(discriminator="kind"),
]


class _MovingMicrophone(SpecModel):
    facing: Literal["walk", "fixed"] = Field(
        "walk",
        description="Where a moving microphone faces: 'walk' turns its front (and an "
        "array's capsules, a head's ears) to its horizontal direction of travel, yaw_deg "
        "added; 'fixed' keeps yaw_deg throughout.",
    )
    span: Literal["speech", "clip"] = Field(
        "clip",
        description="What the microphone's walk spans when speed_m_s is null: the group's "
        "speech (from its first utterance to the end of its last, all speakers) or the whole "
        "clip. With a speed, the walk starts at the start of this span.",
    )


class MicrophoneLineTrajectorySpec(_MovingMicrophone, LineTrajectorySpec):
    """A microphone carried along a straight line between two fixed points."""

    start_m: Vec3 = Field(description="Start point, metres.")
    end_m: Vec3 = Field(description="End point, metres.")


class MicrophoneWaypointsTrajectorySpec(_MovingMicrophone, WaypointsTrajectorySpec):
    """A microphone carried along a polyline through fixed points."""


MicrophoneTrajectorySpec = Annotated[
    StaticTrajectorySpec | MicrophoneLineTrajectorySpec | MicrophoneWaypointsTrajectorySpec,
    Field(discriminator="kind"),
]
