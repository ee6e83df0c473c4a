"""Stage ``navigation``: floors and walkable grids of a scene."""

from __future__ import annotations

from sonicspec import artifacts
from sonicspec.geometry.navigation import NavigationSettings, build_navigation
from sonicspec.plan.params import NavigationParams
from sonicspec.stages.context import JobContext


def settings_from(params: NavigationParams) -> NavigationSettings:
    return NavigationSettings(walker_radius_m=params.walker_radius_m,
                              walker_height_m=params.walker_height_m)


def run(ctx: JobContext) -> None:
    mesh_art = ctx.input("mesh")
    mesh = artifacts.read_mesh(mesh_art.arrays, mesh_art.data)
    nav = build_navigation(mesh, settings_from(ctx.params))
    scene_id = artifacts.decode("mesh", mesh_art.data, ctx.job.label).scene_id
    ctx.write(*artifacts.navigation_arrays(nav, scene_id))
