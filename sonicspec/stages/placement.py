"""Stage ``placement``: mic, sources and trajectories of every group in a shard.

Each group draws from its own generator (spec seed, step, group id), so a group's placement
does not depend on which shard it is in. The RIR points of every source (the path resampled at
the spec's ``rir_spacing_m``) are stored with the placement for the tracer.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np

from sonicspec import artifacts
from sonicspec.errors import PlacementError
from sonicspec.geometry.navigation import cumulative_length, resample_polyline
from sonicspec.geometry.placement import PlacementSettings, sample_placement
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
    rules = params.placement.model_dump()
    names = {f.name for f in fields(PlacementSettings)} & set(rules)
    mic_path = _fixed_path(params.microphone.trajectory, None, None)
    if mic_path is not None and rules.get("mic_position_m") is None:
        rules["mic_position_m"] = mic_path[0]  # a moving microphone starts its walk there
    return PlacementSettings(**{name: rules[name] for name in names},
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


def _with_rir_points(source: dict[str, Any], spacing_m: float | None) -> dict[str, Any]:
    path = np.asarray(source["path_m"], dtype=np.float64)
    points = path[:1] if spacing_m is None else resample_polyline(path, spacing_m)
    source = dict(source)
    source["rir_points_m"] = points.tolist()
    source["rir_points_distance_m"] = cumulative_length(points).tolist()
    return source


def place_group(nav, settings: PlacementSettings, params: PlacementParams, group: str,
                rng: np.random.Generator) -> dict[str, Any]:
    """One group's placement as JSON data, with RIR points per source."""
    trajectory = params.trajectory
    placement = sample_placement(
        nav, settings, scene_id=params.scene_id,
        speech=[_MOTION[trajectory.kind]] * params.speakers, noise=params.noise,
        music=params.music, rng=rng,
    )
    spacing = getattr(trajectory, "rir_spacing_m", None)
    speech = []
    for source in placement.speech:
        entry = source.to_dict()
        fixed = _fixed_path(trajectory, source.start_m, source.end_m)
        if fixed is not None:
            entry.update(motion=trajectory.kind, path_m=fixed, start_m=fixed[0], end_m=fixed[-1],
                         path_length_m=float(cumulative_length(np.asarray(fixed))[-1]))
        moving = entry["motion"] != "static"
        speech.append(_with_rir_points(entry, spacing if moving else None))
    data = placement.to_dict()
    data["speech"] = speech
    for kind in ("noise", "music"):
        if data[kind] is not None:
            data[kind] = _with_rir_points(data[kind], None)
    mic_traj = params.microphone.trajectory
    if isinstance(mic_traj, StaticTrajectorySpec):
        data["mic_path_m"] = [data["mic_m"]]
    else:
        fixed = _fixed_path(mic_traj, placement.mic_m, placement.mic_m)
        if fixed is None:
            raise PlacementError(
                f"group {group}: microphone.trajectory kind {mic_traj.kind!r} needs fixed "
                "points (use 'line' with start_m and end_m, or 'waypoints')")
        data["mic_path_m"] = resample_polyline(np.asarray(fixed), mic_traj.rir_spacing_m).tolist()
    data["group"] = group
    return data


def run(ctx: JobContext) -> None:
    nav_art = ctx.input("navigation")
    nav = artifacts.read_navigation(nav_art.arrays, nav_art.data)
    params: PlacementParams = ctx.params
    settings = settings_from(params)
    groups = [place_group(nav, settings, params, g, ctx.rng("placement", g))
              for g in params.groups]
    ctx.write({"group_count": np.array([len(groups)], dtype=np.int64)},
              artifacts.encode("placement", {"groups": groups}))
