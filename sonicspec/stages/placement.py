"""Stage ``placement``: mic, sources and trajectories of every group in a shard.

Each group draws from its own generator (spec seed, step, group id), so a group's placement
does not depend on which shard it is in. The RIR points of every source (the path resampled at
the spec's ``rir_spacing_m``) are stored with the placement for the tracer.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from sonicspec import artifacts
from sonicspec.errors import PlacementError
from sonicspec.geometry.navigation import cumulative_length, resample_polyline
from sonicspec.geometry.placement import PlacementSettings, sample_placement
from sonicspec.geometry.placement import SourcePlacement as LibrarySource
from sonicspec.plan.params import PlacementParams
from sonicspec.spec.trajectory import (
    LineTrajectorySpec,
    StaticTrajectorySpec,
    TrajectorySpec,
    WaypointsTrajectorySpec,
)
from sonicspec.stages.context import JobContext

_MOTION = {"static": "static", "line": "line", "shortest_path": "shortest_path",
           "waypoints": "static"}


def settings_from(params: PlacementParams) -> PlacementSettings:
    """The library's settings: the spec's placement rules (same names), the mic height and
    the trajectory's smoothing."""
    rules = params.placement.model_dump(include={f.name for f in fields(PlacementSettings)})
    mic_path = _fixed_path(params.microphone.trajectory, None, None)
    if mic_path is not None and params.placement.mic_position_m is None:
        # a moving microphone starts its walk there
        rules.update(mic_position_m=mic_path[0])
    return PlacementSettings(**rules,
                             mic_path_m=None if mic_path is None else tuple(map(tuple, mic_path)),
                             mic_height_m=params.microphone.height_m,
                             smooth_paths=getattr(params.trajectory, "smooth", True))


def _fixed_path(trajectory: TrajectorySpec, start_m, end_m) -> list[list[float]] | None:
    """A path the spec fixes (waypoints, or a line; ends it leaves open are the drawn
    ``start_m`` and ``end_m``), else None."""
    if isinstance(trajectory, WaypointsTrajectorySpec):
        return [list(map(float, p)) for p in trajectory.points_m]
    if isinstance(trajectory, LineTrajectorySpec):
        start = trajectory.start_m or start_m
        end = trajectory.end_m or end_m
        return [list(map(float, start)), list(map(float, end))]
    return None


def _placed(source: LibrarySource, trajectory: TrajectorySpec | None,
            spacing_m: float | None) -> artifacts.SourcePlacement:
    """A drawn source as the placement artifact keeps it: the path the spec fixes (waypoints,
    a line) in place of the drawn one, and its RIR points (every ``spacing_m`` along a moving
    source's path, one point for a static source)."""
    motion, start, end = source.motion, source.start_m, source.end_m
    path = np.asarray(source.path_m, dtype=np.float64)
    length = float(source.path_length_m)
    fixed = None if trajectory is None else _fixed_path(trajectory, start, end)
    if fixed is not None:
        motion, path, start, end = trajectory.kind, np.asarray(fixed), fixed[0], fixed[-1]
        length = float(cumulative_length(path)[-1])
    moving = motion != "static" and spacing_m is not None
    points = resample_polyline(path, spacing_m) if moving else path[:1]
    return artifacts.SourcePlacement(
        motion=motion, start_m=_vec3(start), end_m=_vec3(end), path_m=path.tolist(),
        path_length_m=length, floor_index=int(source.floor_index),
        height_m=float(source.height_m), rir_points_m=points.tolist(),
        rir_points_distance_m=cumulative_length(points).tolist())


def _vec3(v) -> tuple[float, float, float]:
    x, y, z = (float(c) for c in v)
    return x, y, z


def place_group(nav, settings: PlacementSettings, params: PlacementParams, group: str,
                rng: np.random.Generator) -> artifacts.GroupPlacement:
    """One group's placement, with RIR points per source."""
    trajectory = params.trajectory
    placement = sample_placement(
        nav, settings, scene_id=params.scene_id,
        speech=[_MOTION[trajectory.kind]] * params.speakers, noise=params.noise,
        music=params.music, rng=rng,
    )
    spacing = getattr(trajectory, "rir_spacing_m", None)
    mic_traj = params.microphone.trajectory
    if isinstance(mic_traj, StaticTrajectorySpec):
        mic_path = [_vec3(placement.mic_m)]
    else:
        fixed = _fixed_path(mic_traj, placement.mic_m, placement.mic_m)
        if fixed is None:
            raise PlacementError(
                f"group {group}: microphone.trajectory kind {mic_traj.kind!r} needs fixed "
                "points (use 'line' with start_m and end_m, or 'waypoints')")
        mic_path = resample_polyline(np.asarray(fixed), mic_traj.rir_spacing_m).tolist()
    return artifacts.GroupPlacement(
        group=group, scene_id=placement.scene_id, floor_index=int(placement.floor_index),
        mic_m=_vec3(placement.mic_m), mic_path_m=mic_path,
        speech=[_placed(s, trajectory, spacing) for s in placement.speech],
        noise=None if placement.noise is None else _placed(placement.noise, None, None),
        music=None if placement.music is None else _placed(placement.music, None, None),
        tries=int(placement.tries), restarts=int(placement.restarts))


def run(ctx: JobContext) -> None:
    nav_art = ctx.input("navigation")
    nav = artifacts.read_navigation(nav_art.arrays, nav_art.data)
    params: PlacementParams = ctx.params
    settings = settings_from(params)
    groups = [place_group(nav, settings, params, g, ctx.rng("placement", g))
              for g in params.groups]
    ctx.write({"group_count": np.array([len(groups)], dtype=np.int64)},
              artifacts.encode("placement", artifacts.PlacementData(groups=groups)))
