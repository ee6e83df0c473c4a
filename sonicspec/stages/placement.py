"""Stage ``placement``: mic, sources and trajectories of every group in a shard.

Each group draws from its own generator (spec seed, step, group id), so a group's placement
does not depend on which shard it is in. The RIR points of every source (the path resampled at
the spec's ``rir_spacing_m``) are stored with the placement for the tracer.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sonicspec.errors import PlacementError
from sonicspec.geometry.navigation import cumulative_length, resample_polyline
from sonicspec.geometry.placement import PlacementSettings, sample_placement
from sonicspec.stages.context import JobContext
from sonicspec.stages.navigation import load_navigation

_MOTION = {"static": "static", "line": "line", "shortest_path": "shortest_path",
           "waypoints": "static"}


def settings_from(params: dict[str, Any]) -> PlacementSettings:
    p = dict(params["placement"])
    return PlacementSettings(
        source_start_distance_m=tuple(p["source_start_distance_m"]),
        source_end_distance_m=tuple(p["source_end_distance_m"]),
        source_travel_distance_m=tuple(p["source_travel_distance_m"]),
        noise_distance_m=tuple(p["noise_distance_m"]),
        music_distance_m=tuple(p["music_distance_m"]),
        min_source_separation_m=p["min_source_separation_m"],
        min_path_distance_m=p["min_path_distance_m"],
        same_floor=p["same_floor"],
        wall_clearance_m=p["wall_clearance_m"],
        obstacle_clearance_m=p["obstacle_clearance_m"],
        source_height_m=tuple(p["source_height_m"]),
        noise_height_m=tuple(p["noise_height_m"]),
        mic_position_m=None if p["mic_position_m"] is None else tuple(p["mic_position_m"]),
        max_tries=p["max_tries"],
        walker_radius_m=p["walker_radius_m"],
        walker_height_m=p["walker_height_m"],
        mic_height_m=params["microphone"]["height_m"],
    )


def _fixed_path(trajectory: dict[str, Any], drawn: dict[str, Any]) -> list[list[float]] | None:
    """A path the spec fixes (waypoints, or a line with both ends given), else None."""
    if trajectory["kind"] == "waypoints":
        return [list(map(float, p)) for p in trajectory["points_m"]]
    if trajectory["kind"] == "line":
        start = trajectory.get("start_m") or drawn["start_m"]
        end = trajectory.get("end_m") or drawn["end_m"]
        return [list(map(float, start)), list(map(float, end))]
    return None


def _with_rir_points(source: dict[str, Any], spacing_m: float | None) -> dict[str, Any]:
    path = np.asarray(source["path_m"], dtype=np.float64)
    points = path[:1] if spacing_m is None else resample_polyline(path, spacing_m)
    source = dict(source)
    source["rir_points_m"] = points.tolist()
    source["rir_points_distance_m"] = cumulative_length(points).tolist()
    return source


def place_group(nav, settings: PlacementSettings, params: dict[str, Any], group: str,
                rng: np.random.Generator) -> dict[str, Any]:
    """One group's placement as JSON data, with RIR points per source."""
    trajectory = params["trajectory"]
    motion = _MOTION[trajectory["kind"]]
    placement = sample_placement(
        nav, settings, scene_id=params["scene_id"], speech=[motion] * params["speakers"],
        noise=params["noise"], music=params["music"], rng=rng,
    ).to_dict()
    spacing = trajectory.get("rir_spacing_m")
    speech = []
    for source in placement["speech"]:
        fixed = _fixed_path(trajectory, source)
        if fixed is not None:
            source = dict(source, motion=trajectory["kind"], path_m=fixed, start_m=fixed[0],
                          end_m=fixed[-1],
                          path_length_m=float(cumulative_length(np.asarray(fixed))[-1]))
        speech.append(_with_rir_points(source, spacing if source["motion"] != "static" else None))
    placement["speech"] = speech
    for kind in ("noise", "music"):
        if placement[kind] is not None:
            placement[kind] = _with_rir_points(placement[kind], None)
    mic_traj = params["microphone"]["trajectory"]
    if mic_traj["kind"] == "static":
        placement["mic_path_m"] = [placement["mic_m"]]
    else:
        fixed = _fixed_path(mic_traj, {"start_m": placement["mic_m"], "end_m": placement["mic_m"]})
        if fixed is None:
            raise PlacementError(
                f"group {group}: microphone.trajectory kind {mic_traj['kind']!r} needs fixed "
                "points (use 'line' with start_m and end_m, or 'waypoints')")
        points = resample_polyline(np.asarray(fixed), mic_traj["rir_spacing_m"])
        placement["mic_path_m"] = points.tolist()
    placement["group"] = group
    return placement


def run(ctx: JobContext) -> None:
    nav_art = ctx.input("navigation")
    nav = load_navigation(nav_art.arrays, nav_art.data)
    settings = settings_from(ctx.params)
    groups = [place_group(nav, settings, ctx.params, g, ctx.rng("placement", g))
              for g in ctx.params["groups"]]
    ctx.write({"group_count": np.array([len(groups)], dtype=np.int64)}, {"groups": groups})
