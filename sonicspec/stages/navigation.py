"""Stage ``navigation``: floors and walkable grids of a scene."""

from __future__ import annotations

from typing import Any

import numpy as np

from sonicspec.geometry.navigation import (
    Floor,
    Navigation,
    NavigationSettings,
    WalkableGrid,
    build_navigation,
)
from sonicspec.stages.context import JobContext
from sonicspec.stages.mesh import load_scene_mesh

GRID_ARRAYS = ("floor_z_m", "wall_distance_m", "obstacle_distance_m", "walkable", "component")


def settings_from(params: dict[str, Any]) -> NavigationSettings:
    return NavigationSettings(walker_radius_m=params["walker_radius_m"],
                              walker_height_m=params["walker_height_m"])


def run(ctx: JobContext) -> None:
    mesh_art = ctx.input("mesh")
    mesh = load_scene_mesh(mesh_art.arrays, mesh_art.data)
    nav = build_navigation(mesh, settings_from(ctx.params))
    arrays: dict[str, np.ndarray] = {}
    floors = []
    for k, grid in enumerate(nav.grids):
        for name in GRID_ARRAYS:
            arrays[f"floor{k}/{name}"] = np.asarray(getattr(grid, name))
        floors.append({**grid.to_dict(), "distance_limit_m": grid.distance_limit_m})
    ctx.write({name.replace("/", "_"): a for name, a in arrays.items()},
              {"scene_id": mesh_art.data["scene_id"], "floors": floors})


def load_navigation(arrays: dict[str, np.ndarray], data: dict[str, Any]) -> Navigation:
    """The :class:`Navigation` stored by :func:`run`."""
    floors, grids = [], []
    for k, f in enumerate(data["floors"]):
        floor = Floor(**f["floor"])
        floors.append(floor)
        grids.append(WalkableGrid(
            floor=floor, cell_m=f["cell_m"], origin_xy_m=np.asarray(f["origin_xy_m"]),
            walker_radius_m=f["walker_radius_m"], walker_height_m=f["walker_height_m"],
            distance_limit_m=f["distance_limit_m"],
            **{name: arrays[f"floor{k}_{name}"] for name in GRID_ARRAYS},
        ))
    return Navigation(floors=tuple(floors), grids=tuple(grids))
