"""The placement sampler: mic, speech sources with their paths, noise and music (DESIGN.md §4).

The SonicSet recipe puts, on one floor, a microphone; each speech source's start 1–8 m from
the mic; its end point 1–8 m from both the mic and the start, joined by the shortest walkable
path; a static noise and a static music source 1–8 m from the mic. sonicspec enforces the
rules the released scripts skip: every distance range (3-D distances), wall and obstacle
clearances, the same floor, a minimum separation between sources, reachability, and a
minimum distance between the mic and every point of a moving source's path
(``min_path_distance_m``: a path that comes closer restarts the group's draw).

How positions are drawn
-----------------------
A position is *eligible* when it lies on a walkable cell (see
:mod:`sonicspec.geometry.navigation`) and its distances to the nearest wall and obstacle are at
least ``wall_clearance_m`` and ``obstacle_clearance_m`` (bilinear in the grid's distance fields).
Every position of a group lies in the mic's walkable component (reachable on foot from the mic)
when ``same_floor`` holds; otherwise positions may lie on any floor, but a moving source's end
point is always on its start's floor and component (paths do not take stairs).

Draws are rejection sampling, uniform over the eligible area: a candidate is a uniformly drawn
cell among those within the largest allowed horizontal distance of its anchor(s), plus a uniform
point in that cell and a height uniform in its range; it is kept if it meets every rule. Items
are drawn in order (mic; per speech source its start then its end; noise; music); when an item
fails ``item_budget`` candidates in a row the group restarts from a new mic (a mic in a closet
cannot host sources 1–8 m away). Every candidate counts as one try; after ``max_tries`` tries
:class:`~sonicspec.errors.PlacementError` names the scene, the item that failed most and the
rule that rejected it most often. Everything comes from the ``numpy.random.Generator`` passed
in, so a seed gives one placement.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from sonicspec.errors import PlacementError
from sonicspec.geometry.navigation import (
    Navigation,
    NavigationSettings,
    WalkableGrid,
    shortest_path,
)

__all__ = [
    "MOTIONS",
    "Placement",
    "PlacementSettings",
    "SourcePlacement",
    "sample_placement",
]

#: How a speech source moves: stays put, walks a straight line, or the shortest walkable path.
MOTIONS = ("static", "line", "shortest_path")

_BATCH = 32  # candidates drawn at once (vectorised checks); each one counts as a try


def _range(name: str, value: Sequence[float], *, positive: bool) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise PlacementError(
            f"PlacementSettings.{name}: expected a pair [min, max] in metres, got {value!r}"
        ) from None
    floor_ok = low > 0 if positive else low >= 0
    if not (math.isfinite(low) and math.isfinite(high) and floor_ok and low <= high):
        bound = "> 0" if positive else ">= 0"
        raise PlacementError(
            f"PlacementSettings.{name}: expected finite [min, max] with min {bound} and "
            f"min <= max, metres, got {list(value)!r}"
        )
    return (low, high)


@dataclass(frozen=True)
class PlacementSettings:
    """Placement rules; the same fields as the spec's ``PlacementSpec`` plus the mic height.

    Distances are 3-D, metres. ``walker_radius_m`` and ``walker_height_m`` are used when the
    navigation is built (:meth:`navigation_settings`); ``mic_height_m`` comes from the
    microphone spec. ``item_budget`` bounds the candidates spent on one item before the group
    restarts from a new mic. ``smooth_paths`` string-pulls shortest paths (the trajectory
    spec's ``smooth``); without it they are 8-connected grid paths.
    """

    source_start_distance_m: tuple[float, float] = (1.0, 8.0)
    source_end_distance_m: tuple[float, float] = (1.0, 8.0)
    source_travel_distance_m: tuple[float, float] = (1.0, 8.0)
    noise_distance_m: tuple[float, float] = (1.0, 8.0)
    music_distance_m: tuple[float, float] = (1.0, 8.0)
    min_source_separation_m: float = 0.5
    min_path_distance_m: float = 0.5
    same_floor: bool = True
    wall_clearance_m: float = 0.3
    obstacle_clearance_m: float = 0.2
    source_height_m: tuple[float, float] = (1.5, 1.8)
    noise_height_m: tuple[float, float] = (0.3, 1.8)
    mic_position_m: tuple[float, float, float] | None = None
    mic_path_m: tuple[tuple[float, float, float], ...] | None = None
    max_tries: int = 2000
    walker_radius_m: float = 0.25
    walker_height_m: float = 1.8
    mic_height_m: float = 1.5
    item_budget: int = 200
    smooth_paths: bool = True

    def __post_init__(self) -> None:
        for name in (
            "source_start_distance_m",
            "source_end_distance_m",
            "source_travel_distance_m",
            "noise_distance_m",
            "music_distance_m",
        ):
            object.__setattr__(self, name, _range(name, getattr(self, name), positive=False))
        for name in ("source_height_m", "noise_height_m"):
            object.__setattr__(self, name, _range(name, getattr(self, name), positive=True))
        for name in ("min_source_separation_m", "min_path_distance_m", "wall_clearance_m",
                     "obstacle_clearance_m"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise PlacementError(
                    f"PlacementSettings.{name}: expected a finite distance >= 0 in metres, "
                    f"got {value!r}"
                )
        for name in ("walker_radius_m", "walker_height_m", "mic_height_m"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise PlacementError(
                    f"PlacementSettings.{name}: expected a finite positive height or radius in "
                    f"metres, got {value!r}"
                )
        for name in ("max_tries", "item_budget"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise PlacementError(
                    f"PlacementSettings.{name}: expected an integer >= 1, got {value!r}"
                )
        if self.mic_position_m is not None:
            mic = np.asarray(self.mic_position_m, dtype=np.float64)
            if mic.shape != (3,) or not np.all(np.isfinite(mic)):
                raise PlacementError(
                    f"PlacementSettings.mic_position_m: expected [x, y, z] in metres or None, "
                    f"got {self.mic_position_m!r}"
                )
            object.__setattr__(self, "mic_position_m", tuple(float(v) for v in mic))
        if self.mic_path_m is not None:
            walk = np.asarray(self.mic_path_m, dtype=np.float64)
            if walk.ndim != 2 or walk.shape[1] != 3 or len(walk) < 1 or not np.all(
                    np.isfinite(walk)):
                raise PlacementError(
                    f"PlacementSettings.mic_path_m: expected [[x, y, z], ...] in metres or "
                    f"None, got {self.mic_path_m!r}"
                )
            object.__setattr__(self, "mic_path_m", tuple(tuple(float(v) for v in p)
                                                         for p in walk))

    def navigation_settings(self, cell_m: float = 0.05) -> NavigationSettings:
        """Navigation settings for the walker these rules assume."""
        return NavigationSettings(
            cell_m=cell_m,
            walker_radius_m=self.walker_radius_m,
            walker_height_m=self.walker_height_m,
        )


@dataclass(frozen=True, eq=False)
class SourcePlacement:
    """Where one source is and how it moves.

    Attributes
    ----------
    motion : str
        ``"static"``, ``"line"`` or ``"shortest_path"``.
    start_m, end_m : (3,) float
        Start and end position, metres (equal for a static source).
    path_m : (N, 3) float
        The polyline walked from start to end (one point for a static source), metres.
    path_length_m : float
        Its length, metres (the geodesic length for a shortest path).
    floor_index : int
        The floor it stands on.
    height_m : float
        Height above the floor (mouth, loudspeaker), metres.
    """

    motion: str
    start_m: np.ndarray
    end_m: np.ndarray
    path_m: np.ndarray
    path_length_m: float
    floor_index: int
    height_m: float

    def to_dict(self) -> dict:
        """Plain JSON-ready dictionary."""
        return {
            "motion": self.motion,
            "start_m": [float(v) for v in self.start_m],
            "end_m": [float(v) for v in self.end_m],
            "path_m": np.asarray(self.path_m, dtype=np.float64).tolist(),
            "path_length_m": float(self.path_length_m),
            "floor_index": int(self.floor_index),
            "height_m": float(self.height_m),
        }


@dataclass(frozen=True, eq=False)
class Placement:
    """One group's positions.

    Attributes
    ----------
    scene_id : str
    floor_index : int
        The mic's floor.
    mic_m : (3,) float
        Microphone (array centre) position, metres.
    speech : tuple of SourcePlacement
        One per speech source, in the order requested.
    noise, music : SourcePlacement or None
        The static noise and music sources, when requested.
    tries : int
        Candidates drawn in all (for diagnostics).
    restarts : int
        Times the group was started again from a new mic (an item ran out of its budget).
    """

    scene_id: str
    floor_index: int
    mic_m: np.ndarray
    speech: tuple[SourcePlacement, ...]
    noise: SourcePlacement | None = None
    music: SourcePlacement | None = None
    tries: int = 0
    restarts: int = 0

    def to_dict(self) -> dict:
        """Plain JSON-ready dictionary (the group metadata's positions and trajectories)."""
        return {
            "scene_id": self.scene_id,
            "floor_index": int(self.floor_index),
            "mic_m": [float(v) for v in self.mic_m],
            "speech": [source.to_dict() for source in self.speech],
            "noise": None if self.noise is None else self.noise.to_dict(),
            "music": None if self.music is None else self.music.to_dict(),
            "tries": int(self.tries),
            "restarts": int(self.restarts),
        }


# --------------------------------------------------------------------------- the sampler
@dataclass
class _Pool:
    """Eligible cells of every floor, flattened (rows: candidates for any position)."""

    xy: np.ndarray  # (n, 2) cell centres
    floor: np.ndarray  # (n,) floor index
    component: np.ndarray  # (n,) walkable component on that floor
    iy: np.ndarray
    ix: np.ndarray


def _eligible_pool(navigation: Navigation, settings: PlacementSettings) -> _Pool:
    parts = []
    for grid in navigation.grids:
        # Cell-centre test with the clearance; the point drawn in the cell is re-checked.
        ok = grid.walkable & (grid.wall_distance_m >= settings.wall_clearance_m - 1e-6)
        ok &= grid.obstacle_distance_m >= settings.obstacle_clearance_m - 1e-6
        iy, ix = np.nonzero(ok)
        parts.append((grid, iy, ix))
    return _Pool(
        xy=np.concatenate([g.cell_centers_xy(iy, ix).reshape(-1, 2) for g, iy, ix in parts]),
        floor=np.concatenate([np.full(iy.size, g.floor.index) for g, iy, _ in parts]),
        component=np.concatenate([g.component[iy, ix] for g, iy, ix in parts]),
        iy=np.concatenate([iy for _, iy, _ in parts]),
        ix=np.concatenate([ix for _, _, ix in parts]),
    )


@dataclass
class _Item:
    label: str  # e.g. "speech source 2's end point"
    failures: Counter = field(default_factory=Counter)
    tries: int = 0
    floor: int | None = None  # the floor it was last drawn on (None: any floor)


def polyline_distance(path: np.ndarray, point: np.ndarray) -> float:
    """Smallest 3-D distance from ``point`` to the polyline ``path`` (N, 3), metres."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(point, dtype=np.float64)
    if len(p) == 1:
        return float(np.linalg.norm(p[0] - q))
    a, b = p[:-1], p[1:]
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.where(length2 > 0, length2, 1.0), 0, 1)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - q, axis=1)))


def polylines_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest 3-D distance between two polylines ``(N, 3)`` and ``(M, 3)``, metres (exact:
    over every pair of segments, the interior closest points where both lie inside their
    segments, else the endpoints against the other segment)."""
    p = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if len(p) == 1 or len(q) == 1:
        return polyline_distance(q, p[0]) if len(p) == 1 else polyline_distance(p, q[0])
    ends = min(min(polyline_distance(q, x) for x in p), min(polyline_distance(p, y) for y in q))
    p0, u = p[:-1, None, :], (p[1:] - p[:-1])[:, None, :]
    q0, v = q[None, :-1, :], (q[1:] - q[:-1])[None, :, :]
    w = p0 - q0
    uu, uv, vv = (u * u).sum(-1), (u * v).sum(-1), (v * v).sum(-1)
    uw, vw = (u * w).sum(-1), (v * w).sum(-1)
    denom = uu * vv - uv**2
    ok = denom > 1e-12 * np.maximum(uu * vv, 1e-30)
    safe = np.where(ok, denom, 1.0)
    sp, tq = (uv * vw - vv * uw) / safe, (uu * vw - uv * uw) / safe
    inside = ok & (sp >= 0) & (sp <= 1) & (tq >= 0) & (tq <= 1)
    if not np.any(inside):
        return float(ends)
    gap = w + sp[..., None] * u - tq[..., None] * v
    return float(min(ends, np.linalg.norm(gap, axis=-1)[inside].min()))


def _near_walk(item: _Item, walk: np.ndarray | None, points: np.ndarray, min_m: float,
               what: str) -> bool:
    """Whether ``points`` (a point or a path) come closer than ``min_m`` to a moving
    microphone's ``walk`` (None: it stands still); counted as ``item``'s failure if so."""
    if walk is None or polylines_distance(points, walk) >= min_m - 1e-9:
        return False
    item.failures[f"{what} than {min_m:g} m to the microphone's walk"] += 1
    return True


def _fmt_range(low: float, high: float) -> str:
    return f"{low:g}–{high:g} m"


class _Sampler:
    def __init__(
        self,
        navigation: Navigation,
        settings: PlacementSettings,
        scene_id: str,
        motions: tuple[str, ...],
        rng: np.random.Generator,
    ) -> None:
        self.nav = navigation
        self.s = settings
        self.scene_id = scene_id
        self.motions = motions
        self.rng = rng
        self.pool = _eligible_pool(navigation, settings)
        self.cell_m = {g.floor.index: g.cell_m for g in navigation.grids}
        self.tries = 0

    # -- candidate drawing -------------------------------------------------------------
    def _grid(self, floor: int) -> WalkableGrid:
        return self.nav.grids[floor]

    def _candidates(
        self, mask: np.ndarray, heights: tuple[float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """n candidates uniform over the masked cells: points, floors, components, heights."""
        rows = np.flatnonzero(mask)
        pick = rows[self.rng.integers(0, rows.size, size=n)]
        floors = self.pool.floor[pick]
        cell = np.array([self.cell_m[f] for f in floors])
        xy = self.pool.xy[pick] + (self.rng.random((n, 2)) - 0.5) * cell[:, None]
        height = self.rng.uniform(heights[0], heights[1], size=n)
        z = np.empty(n)
        for f in np.unique(floors):
            grid = self._grid(int(f))
            on = floors == f
            z[on] = grid.floor_z_m[self.pool.iy[pick[on]], self.pool.ix[pick[on]]] + height[on]
        return np.column_stack([xy, z]), floors, self.pool.component[pick], height

    def _clear(self, points: np.ndarray, floors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        wall_ok = np.ones(points.shape[0], bool)
        obstacle_ok = np.ones(points.shape[0], bool)
        for f in np.unique(floors):
            grid = self._grid(int(f))
            on = floors == f
            wall_ok[on] = grid.wall_distance_at(points[on]) >= self.s.wall_clearance_m - 1e-9
            obstacle_ok[on] = (
                grid.obstacle_distance_at(points[on]) >= self.s.obstacle_clearance_m - 1e-9
            )
        return wall_ok, obstacle_ok

    def draw(
        self,
        item: _Item,
        heights: tuple[float, float],
        anchors: list[tuple[str, np.ndarray, tuple[float, float]]],
        floor: int | None,
        component: int | None,
        separated_from: list[np.ndarray],
        line_from: np.ndarray | None = None,
    ):
        """Draw one position for ``item`` within its budget; None when the budget runs out.

        ``anchors`` are (name, point, (min, max) distance) rules; ``floor``/``component``
        restrict the cells; ``separated_from`` are points to keep ``min_source_separation_m``
        from; ``line_from`` asks for a walkable straight line from that point.
        """
        mask = np.ones(self.pool.floor.shape[0], bool)
        if floor is not None:
            mask &= self.pool.floor == floor
        if component is not None:
            mask &= self.pool.component == component
        for _, point, (_, high) in anchors:
            # 3-D distance <= high needs horizontal distance <= high (plus the in-cell jitter).
            reach = high + max(self.cell_m.values())
            mask &= np.sum((self.pool.xy - point[:2]) ** 2, axis=1) <= reach**2
        item.floor = floor
        budget = self.s.item_budget
        used = 0
        while used < budget and self.tries < self.s.max_tries:
            n = min(_BATCH, budget - used, self.s.max_tries - self.tries)
            if not np.any(mask):
                # Nothing eligible within reach: each attempt fails on the first rule.
                reason = anchors[0][0] if anchors else "walkable area with clearance"
                item.failures[reason] += n
                item.tries += n
                self.tries += n
                used += n
                continue
            points, floors, comps, height = self._candidates(mask, heights, n)
            reasons = np.full(n, "", dtype=object)
            wall_ok, obstacle_ok = self._clear(points, floors)
            reasons[~wall_ok] = f"wall clearance >= {self.s.wall_clearance_m:g} m"
            rest = reasons == ""
            reasons[rest & ~obstacle_ok] = (
                f"obstacle clearance >= {self.s.obstacle_clearance_m:g} m"
            )
            for name, point, (low, high) in anchors:
                d = np.linalg.norm(points - point, axis=1)
                bad = (reasons == "") & ((d < low) | (d > high))
                reasons[bad] = name
            if separated_from and self.s.min_source_separation_m > 0:
                others = np.asarray(separated_from)
                d = np.linalg.norm(points[:, None, :] - others[None, :, :], axis=2).min(axis=1)
                bad = (reasons == "") & (d < self.s.min_source_separation_m)
                reasons[bad] = (
                    f"separation from other sources >= {self.s.min_source_separation_m:g} m"
                )
            for k in range(n):
                if reasons[k] == "" and line_from is not None:
                    grid = self._grid(int(floors[k]))
                    if not grid.line_of_sight(line_from[:2], points[k, :2]):
                        reasons[k] = "walkable straight line from the start"
                if reasons[k] == "":
                    item.tries += k + 1
                    self.tries += k + 1
                    return points[k], int(floors[k]), int(comps[k]), float(height[k])
                item.failures[reasons[k]] += 1
            item.tries += n
            self.tries += n
            used += n
        return None

    # -- the group ---------------------------------------------------------------------
    def fixed_mic(self) -> tuple[np.ndarray, int, int]:
        mic = np.asarray(self.s.mic_position_m, dtype=np.float64)
        best = None
        for grid in self.nav.grids:
            z_floor = float(grid.floor_height_at(mic)[()])
            comp = int(grid.component_at(mic)[()])
            if comp >= 0 and z_floor < mic[2] <= z_floor + grid.walker_height_m:
                if best is None or z_floor > best[0]:
                    best = (z_floor, grid.floor.index, comp)
        if best is None:
            raise PlacementError(
                f"scene {self.scene_id!r}: mic_position_m: expected a point above the walkable "
                f"area of a floor (below head height), got {mic.round(3).tolist()}"
            )
        return mic, best[1], best[2]

    def run(self, noise: bool, music: bool) -> Placement:
        s = self.s
        same = s.same_floor
        items: dict[str, _Item] = {"mic": _Item("the microphone")}
        # A moving microphone: every source keeps min_path_distance_m from its whole walk
        # (where it will be when is the arrangement's, later: the walk bounds it).
        walk = None if s.mic_path_m is None else np.asarray(s.mic_path_m, dtype=np.float64)
        restarts = -1
        while self.tries < s.max_tries:
            restarts += 1
            if s.mic_position_m is not None:
                mic, mic_floor, mic_comp = self.fixed_mic()
            else:
                got = self.draw(items["mic"], (s.mic_height_m, s.mic_height_m), [], None, None, [])
                if got is None:
                    break
                mic, mic_floor, mic_comp, _ = got
            floor = mic_floor if same else None
            comp = mic_comp if same else None
            mic_rule = "distance from the mic {}"
            starts: list[np.ndarray] = []
            speech: list[SourcePlacement] = []
            failed = False
            for i, motion in enumerate(self.motions):
                label = f"speech source {i}"
                item = items.setdefault(f"start{i}", _Item(f"{label}'s start point"))
                rule = mic_rule.format(_fmt_range(*s.source_start_distance_m))
                got = self.draw(
                    item,
                    s.source_height_m,
                    [(rule, mic, s.source_start_distance_m)],
                    floor,
                    comp,
                    starts,
                )
                if got is None:
                    failed = True
                    break
                start, start_floor, start_comp, height = got
                if _near_walk(item, walk, start, s.min_path_distance_m, "closer"):
                    failed = True
                    break
                if motion == "static":
                    speech.append(
                        SourcePlacement(motion, start, start, start[None], 0.0, start_floor, height)
                    )
                    starts.append(start)
                    continue
                item = items.setdefault(f"end{i}", _Item(f"{label}'s end point"))
                anchors = [
                    (
                        mic_rule.format(_fmt_range(*s.source_end_distance_m)),
                        mic,
                        s.source_end_distance_m,
                    ),
                    (
                        f"distance from the start {_fmt_range(*s.source_travel_distance_m)}",
                        start,
                        s.source_travel_distance_m,
                    ),
                ]
                got = self.draw(
                    item,
                    (height, height),
                    anchors,
                    start_floor,
                    start_comp,
                    [],
                    line_from=start if motion == "line" else None,
                )
                if got is None:
                    failed = True
                    break
                end = got[0]
                grid = self._grid(start_floor)
                if motion == "line":
                    path = np.stack([start, end])
                    length = float(np.linalg.norm(end - start))
                else:
                    nav_path = shortest_path(
                        grid, start, end, height_m=height, smooth=s.smooth_paths
                    )
                    path = nav_path.points_m.copy()
                    # The path's ends are the drawn points exactly (same xy; z from the floor).
                    path[0], path[-1] = start, end
                    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
                closest = polyline_distance(path, mic)
                if closest < s.min_path_distance_m - 1e-9:
                    items[f"end{i}"].failures[
                        f"a path closer than {s.min_path_distance_m:g} m to the mic"] += 1
                    failed = True
                    break
                if _near_walk(items[f"end{i}"], walk, path, s.min_path_distance_m,
                              "a path closer"):
                    failed = True
                    break
                speech.append(
                    SourcePlacement(motion, start, end, path, length, start_floor, height)
                )
                starts.append(start)
            statics: dict[str, SourcePlacement | None] = {"noise": None, "music": None}
            for name, wanted, distance in (
                ("noise", noise, s.noise_distance_m),
                ("music", music, s.music_distance_m),
            ):
                if failed or not wanted:
                    continue
                item = items.setdefault(name, _Item(f"the {name} source"))
                rule = mic_rule.format(_fmt_range(*distance))
                got = self.draw(
                    item, s.noise_height_m, [(rule, mic, distance)], floor, comp, starts
                )
                if got is None:
                    failed = True
                    break
                point, point_floor, _, height = got
                if _near_walk(item, walk, point, s.min_path_distance_m, "closer"):
                    failed = True
                    break
                statics[name] = SourcePlacement(
                    "static", point, point, point[None], 0.0, point_floor, height
                )
                starts.append(point)
            if not failed:
                return Placement(
                    scene_id=self.scene_id,
                    floor_index=mic_floor,
                    mic_m=mic,
                    speech=tuple(speech),
                    noise=statics["noise"],
                    music=statics["music"],
                    tries=self.tries,
                    restarts=restarts,
                )
        raise self._error(items)

    def _error(self, items: dict[str, _Item]) -> PlacementError:
        worst = max(items.values(), key=lambda it: sum(it.failures.values()))
        if not worst.failures:  # pragma: no cover - max_tries >= 1 always records a failure
            worst = items["mic"]
        reason, count = worst.failures.most_common(1)[0] if worst.failures else ("no attempt", 0)
        where = "on any floor" if worst.floor is None else f"on floor {worst.floor}"
        return PlacementError(
            f"scene {self.scene_id!r}: could not place {worst.label} {where}: expected a "
            f"position meeting every placement rule within {self.s.max_tries} tries, got none "
            f"(most failed: {reason}, {count} of {worst.tries} tries for it); widen the "
            "distance ranges, lower the clearances or pick a larger scene"
        )


def sample_placement(
    navigation: Navigation,
    settings: PlacementSettings,
    *,
    scene_id: str,
    speech: Sequence[str],
    noise: bool,
    music: bool,
    rng: np.random.Generator,
) -> Placement:
    """Draw one group's mic, speech sources (with paths), noise and music positions.

    Parameters
    ----------
    navigation : Navigation
        Floors and walkable grids of the scene
        (:func:`~sonicspec.geometry.navigation.build_navigation`).
    settings : PlacementSettings
        The placement rules.
    scene_id : str
        Scene name, for error messages and the result.
    speech : sequence of str
        The motion of each speech source: ``"static"``, ``"line"`` or ``"shortest_path"``.
    noise, music : bool
        Whether to place the static noise / music source.
    rng : numpy.random.Generator
        The only source of randomness (same generator state, same placement).

    Returns
    -------
    Placement

    Raises
    ------
    PlacementError
        An unknown motion, a fixed mic off the walkable area, no eligible position in the
        whole scene, or no placement meeting the rules within ``settings.max_tries`` tries
        (the message names the scene, the item and the rule that failed most).
    """
    motions = tuple(str(m) for m in speech)
    for i, motion in enumerate(motions):
        if motion not in MOTIONS:
            raise PlacementError(
                f"sample_placement.speech[{i}]: expected one of {list(MOTIONS)}, got {motion!r}"
            )
    sampler = _Sampler(navigation, settings, str(scene_id), motions, rng)
    if sampler.pool.floor.size == 0:
        raise PlacementError(
            f"scene {scene_id!r}: expected walkable area with wall clearance >= "
            f"{settings.wall_clearance_m:g} m and obstacle clearance >= "
            f"{settings.obstacle_clearance_m:g} m on some floor, got none; lower the "
            "clearances or the walker radius"
        )
    return sampler.run(noise, music)
