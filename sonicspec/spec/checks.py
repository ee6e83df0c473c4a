"""Semantic checks: the rules JSON Schema cannot express, all reported at once.

They run on a structurally valid :class:`~sonicspec.spec.dataset.DatasetSpec` and return
:class:`~sonicspec.spec.load.Problem` objects (errors and warnings) with document paths; the
loader attaches line numbers. ``check_files`` adds the checks that need the file system.
"""

from __future__ import annotations

import fnmatch
import glob
import math
import posixpath
from collections.abc import Collection, Iterator
from pathlib import Path

from sonicspec.errors import SonicspecError
from sonicspec.shares import split_shares
from sonicspec.spec.augmentation import mp3_bitrates_at
from sonicspec.spec.corpora import (
    FmaCorpusSpec,
    FolderCorpusSpec,
    Fsd50kCorpusSpec,
    GeneratedSpeechSpec,
    LibriSpeechCorpusSpec,
)
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.load import Problem, did_you_mean
from sonicspec.spec.materials import library_material_names
from sonicspec.spec.microphone import channel_count
from sonicspec.spec.mixture import EnhancementTaskSpec, SeparationTaskSpec
from sonicspec.spec.scene import (
    BoxObstacleSpec,
    CylinderObstacleSpec,
    MeshObstacleSpec,
    MeshSceneSpec,
    PolygonSceneSpec,
)
from sonicspec.spec.trajectory import (
    LineTrajectorySpec,
    StaticTrajectorySpec,
    WaypointsTrajectorySpec,
)
from sonicspec.units import bands_below_nyquist

Point2 = tuple[float, float]

MIN_RAYS_WITHOUT_WARNING = 2000
# Above this share of guided directions the plain ones are too few (bench_rlr, session 6).
MAX_GUIDING_WITHOUT_WARNING = 0.5
# A quarter of the wavelength at 4 kHz (8.6 cm): surfaces moved further change the highest
# bands' reflections.
MAX_SIMPLIFY_WITHOUT_WARNING_M = 0.02


def _err(path: tuple, message: str) -> Problem:
    return Problem(tuple(path), message)


def _warn(path: tuple, message: str) -> Problem:
    return Problem(tuple(path), message, severity="warning")


# --- small plane geometry (pure Python: the spec must not need numpy to validate) ----------


def _cross(o: Point2, a: Point2, b: Point2) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _segments_cross(p1: Point2, p2: Point2, q1: Point2, q2: Point2) -> bool:
    """True if the closed segments p1p2 and q1q2 intersect."""
    d1, d2 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    d3, d4 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 * d2 < 0 and d3 * d4 < 0:
        return True

    def on_seg(a: Point2, b: Point2, c: Point2) -> bool:
        return (
            min(a[0], b[0]) - 1e-12 <= c[0] <= max(a[0], b[0]) + 1e-12
            and min(a[1], b[1]) - 1e-12 <= c[1] <= max(a[1], b[1]) + 1e-12
        )

    return (
        (abs(d1) < 1e-12 and on_seg(q1, q2, p1))
        or (abs(d2) < 1e-12 and on_seg(q1, q2, p2))
        or (abs(d3) < 1e-12 and on_seg(p1, p2, q1))
        or (abs(d4) < 1e-12 and on_seg(p1, p2, q2))
    )


def polygon_area(poly: list[Point2]) -> float:
    """Signed area (positive for counter-clockwise)."""
    n = len(poly)
    return 0.5 * sum(
        poly[i][0] * poly[(i + 1) % n][1] - poly[(i + 1) % n][0] * poly[i][1] for i in range(n)
    )


def polygon_self_intersection(poly: list[Point2]) -> tuple[int, int] | None:
    """Indices of two non-adjacent edges that cross, or None for a simple polygon."""
    n = len(poly)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            if _segments_cross(poly[i], poly[(i + 1) % n], poly[j], poly[(j + 1) % n]):
                return i, j
    return None


def point_in_polygon(p: Point2, poly: list[Point2]) -> bool:
    inside = False
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        if (a[1] > p[1]) != (b[1] > p[1]):
            x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            if p[0] < x:
                inside = not inside
    return inside


def distance_to_boundary(p: Point2, poly: list[Point2]) -> float:
    best = math.inf
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        dx, dy = b[0] - a[0], b[1] - a[1]
        length2 = dx * dx + dy * dy
        t = (
            0.0
            if length2 == 0
            else max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2))
        )
        best = min(best, math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy))
    return best


def _inside_room(p: tuple[float, ...], poly: list[Point2], height: float) -> bool:
    return point_in_polygon((p[0], p[1]), poly) and 0.0 <= p[2] <= height


def _box_corners(ob: BoxObstacleSpec) -> list[tuple[float, float, float]]:
    cx, cy, cz = ob.center_m
    hx, hy, hz = (s / 2 for s in ob.size_m)
    c, s = math.cos(math.radians(ob.yaw_deg)), math.sin(math.radians(ob.yaw_deg))
    return [
        (cx + c * dx - s * dy, cy + s * dx + c * dy, cz + dz)
        for dx in (-hx, hx)
        for dy in (-hy, hy)
        for dz in (-hz, hz)
    ]


# --- the checks --------------------------------------------------------------------------


def check_spec(spec: DatasetSpec, *, cli_outputs: Collection[str] = (),
               base_dir: Path | None = None) -> list[Problem]:
    """Every semantic error and warning in ``spec``.

    ``cli_outputs`` names the ``outputs`` folders (``dir``, ``store_dir``) that the command
    line chooses instead of the spec: they may lie outside the spec's folder. ``base_dir``: the
    spec's folder, where the output folders are also checked after resolving symbolic links.
    """
    problems: list[Problem] = list(_check_output_folders(spec, cli_outputs, base_dir))
    for check in (
        _check_scenes,
        _check_materials,
        _check_positions,
        _check_splits,
        _check_corpora,
        _check_mixture,
        _check_acoustics,
        _check_outputs,
        _check_trajectory,
        _check_heights_and_distances,
        _check_augmentation,
        check_directivity,
    ):
        problems.extend(check(spec))
    return problems


def _check_scenes(spec: DatasetSpec) -> Iterator[Problem]:
    first: dict[str, int] = {}
    for i, scene in enumerate(spec.scenes):
        if scene.id in first:
            yield _err(
                ("scenes", i, "id"),
                f"scene id {scene.id!r} is already used by scenes[{first[scene.id]}]; "
                "ids must be unique",
            )
        else:
            first[scene.id] = i
        if scene.kind == "l_shape":
            x, y, _ = scene.size_m
            cx, cy = scene.cutout_m
            if cx >= x or cy >= y:
                yield _err(
                    ("scenes", i, "cutout_m"),
                    f"the cutout must be smaller than the room's floor ({x:g} x {y:g} m), "
                    f"got [{cx:g}, {cy:g}]",
                )
        if isinstance(scene, PolygonSceneSpec):
            poly = scene.floor_polygon()
            crossing = polygon_self_intersection(poly)
            if crossing is not None:
                a, b = crossing
                yield _err(
                    ("scenes", i, "floor_m"),
                    f"the floor polygon crosses itself (edge {a}-{a + 1} meets edge "
                    f"{b}-{(b + 1) % len(poly)}); list the corners in walking order",
                )
            elif abs(polygon_area(poly)) < 1e-6:
                yield _err(("scenes", i, "floor_m"), "the floor polygon has no area")
        if not isinstance(scene, MeshSceneSpec):
            poly, height = scene.floor_polygon(), scene.height()
            for j, ob in enumerate(scene.obstacles):
                where = ("scenes", i, "obstacles", j)
                if isinstance(ob, BoxObstacleSpec):
                    if not all(_inside_room(c, poly, height + 1e-9) for c in _box_corners(ob)):
                        yield _err(
                            (*where, "center_m"), f"the box does not fit inside scene {scene.id!r}"
                        )
                elif isinstance(ob, CylinderObstacleSpec):
                    c = ob.center_xy_m
                    if (
                        not point_in_polygon(c, poly)
                        or distance_to_boundary(c, poly) < ob.radius_m - 1e-9
                        or ob.base_z_m < 0
                        or ob.base_z_m + ob.height_m > height + 1e-9
                    ):
                        yield _err(
                            (*where, "center_xy_m"),
                            f"the cylinder does not fit inside scene {scene.id!r}",
                        )
                elif isinstance(ob, MeshObstacleSpec) and not _inside_room(
                    ob.position_m, poly, height
                ):
                    yield _err(
                        (*where, "position_m"),
                        f"position {list(ob.position_m)} is outside scene {scene.id!r}",
                    )


def _material_refs(spec: DatasetSpec) -> Iterator[tuple[tuple, str]]:
    for i, scene in enumerate(spec.scenes):
        if isinstance(scene, MeshSceneSpec):
            for label, name in scene.label_materials.items():
                yield ("scenes", i, "label_materials", label), name
            if scene.default_material is not None:
                yield ("scenes", i, "default_material"), scene.default_material
        else:
            for part in ("walls", "floor", "ceiling"):
                yield ("scenes", i, "materials", part), getattr(scene.materials, part)
        for j, ob in enumerate(scene.obstacles):
            yield ("scenes", i, "obstacles", j, "material"), ob.material
    for label, name in spec.materials.label_materials.items():
        yield ("materials", "label_materials", label), name


def _check_materials(spec: DatasetSpec) -> Iterator[Problem]:
    known = set(library_material_names(spec.materials.library)) | set(spec.materials.custom)
    for path, name in _material_refs(spec):
        if name not in known:
            yield _err(
                path,
                f"unknown material {name!r} in library "
                f"{spec.materials.library!r}"
                + did_you_mean(name, sorted(known))
                + (
                    " (or define it under materials.custom)"
                    if not did_you_mean(name, sorted(known))
                    else ""
                ),
            )


def _procedural(spec: DatasetSpec) -> list[tuple[int, object]]:
    return [(i, s) for i, s in enumerate(spec.scenes) if not isinstance(s, MeshSceneSpec)]


def _check_positions(spec: DatasetSpec) -> Iterator[Problem]:
    points: list[tuple[tuple, tuple[float, float, float]]] = []
    if spec.placement.mic_position_m is not None:
        points.append((("placement", "mic_position_m"), spec.placement.mic_position_m))
    for prefix, traj in (
        (("trajectory",), spec.trajectory),
        (("microphone", "trajectory"), spec.microphone.trajectory),
    ):
        if isinstance(traj, LineTrajectorySpec):
            for end in ("start_m", "end_m"):
                if getattr(traj, end) is not None:
                    points.append(((*prefix, end), getattr(traj, end)))
        elif isinstance(traj, WaypointsTrajectorySpec):
            points.extend(((*prefix, "points_m", k), p) for k, p in enumerate(traj.points_m))
    for path, p in points:
        for _, scene in _procedural(spec):
            if not _inside_room(p, scene.floor_polygon(), scene.height()):
                yield _err(path, f"position {list(p)} is outside scene {scene.id!r}")
                break


def scene_matches(pattern: str, spec: DatasetSpec) -> list[str]:
    """Scene ids (or mesh-glob id prefixes) that a split's pattern selects, statically."""
    out = []
    for scene in spec.scenes:
        if isinstance(scene, MeshSceneSpec) and glob.has_magic(scene.path):
            # The files are unknown until compile time; a pattern selects this scene family
            # if it names the family or could match one of its members.
            if (
                pattern == scene.id
                or fnmatch.fnmatchcase(scene.id + "/x", pattern)
                or pattern.startswith(scene.id + "/")
            ):
                out.append(scene.id + "/*")
        elif fnmatch.fnmatchcase(scene.id, pattern):
            out.append(scene.id)
    return out


def _check_splits(spec: DatasetSpec) -> Iterator[Problem]:
    owner: dict[str, str] = {}
    pinned: dict[str, str] = {}  # a scene id written out (no glob) -> the split listing it
    for name, split in spec.splits.items():
        matched: list[str] = []
        for k, pattern in enumerate(split.scenes):
            first = split.scenes.index(pattern)
            if first < k:
                yield _err(("splits", name, "scenes", k),
                           f"{pattern!r} is listed twice (also scenes[{first}])")
                continue
            if not glob.has_magic(pattern):
                other = pinned.setdefault(pattern, name)
                if other != name:
                    yield _err(("splits", name, "scenes", k),
                               f"scene {pattern!r} is also listed by split {other!r}; a scene "
                               "belongs to one split")
            hits = scene_matches(pattern, spec)
            if hits == [pattern.split("/")[0] + "/*"] and not glob.has_magic(pattern):
                hits = [pattern]  # one member of a mesh glob, pinned: it alone is taken
            if not hits:
                ids = [s.id for s in spec.scenes]
                yield _err(
                    ("splits", name, "scenes", k),
                    f"{pattern!r} matches no scene id" + did_you_mean(pattern, ids),
                )
            matched.extend(hits)
        matched = sorted(set(matched))
        concrete = [m for m in matched if not m.endswith("/*")]
        if (
            split.scene_count is not None
            and len(concrete) == len(matched)
            and split.scene_count > len(concrete)
        ):
            yield _err(
                ("splits", name, "scene_count"),
                f"asks for {split.scene_count} scenes but its patterns match only {len(concrete)}",
            )
        for sid in matched:
            if sid in owner and owner[sid] != name:
                other = spec.splits[owner[sid]]
                if split.scene_count is None or other.scene_count is None:
                    yield _err(
                        ("splits", name, "scenes"),
                        f"splits {owner[sid]!r} and {name!r} share scene {sid!r}; splits "
                        "must use disjoint scenes (or give both a scene_count to "
                        "partition a shared pool)",
                    )
            else:
                owner.setdefault(sid, name)


def _corpus_split_problems(path: tuple, corpus: object, splits: list[str]) -> Iterator[Problem]:
    if isinstance(corpus, LibriSpeechCorpusSpec):
        for s in splits:
            if s not in corpus.subsets:
                yield _err(
                    (*path, "subsets"),
                    f"no subset feeds split {s!r}" + did_you_mean(s, list(corpus.subsets)),
                )
        used: dict[str, str] = {}
        for s, subsets in corpus.subsets.items():
            if not subsets:
                yield _err((*path, "subsets", s), "lists no subset")
            for sub in subsets:
                if sub in used and used[sub] != s:
                    yield _err(
                        (*path, "subsets", s),
                        f"subset {sub!r} also feeds split {used[sub]!r}; speakers would "
                        "cross splits",
                    )
                used.setdefault(sub, s)
    elif isinstance(corpus, (FolderCorpusSpec, Fsd50kCorpusSpec, FmaCorpusSpec)):
        ratios = corpus.split_ratios or {}
        bad = False
        for s, r in ratios.items():
            if not 0 < r <= 1:
                bad = True
                yield _err((*path, "split_ratios", s), f"shares must lie in (0, 1], got {r:g}")
            elif s not in splits:
                yield _warn(
                    (*path, "split_ratios", s),
                    f"expected shares of the spec's splits ({', '.join(splits)}), got one for "
                    f"{s!r}, which is not used"
                    + did_you_mean(s, [x for x in splits if x not in ratios]),
                )
        if not bad:
            # The corpus stage's own rule, so validate accepts exactly what a build reads.
            try:
                split_shares(corpus.split_ratios, splits)
            except SonicspecError as exc:
                yield _err((*path, "split_ratios"), str(exc))


def _check_corpora(spec: DatasetSpec) -> Iterator[Problem]:
    splits = list(spec.splits)
    c = spec.corpora
    yield from _corpus_split_problems(("corpora", "speech"), c.speech, splits)
    for kind in ("noise", "music"):
        corpus = getattr(c, kind)
        if corpus is not None:
            yield from _corpus_split_problems(("corpora", kind), corpus, splits)
    if (
        isinstance(c.speech, GeneratedSpeechSpec)
        and c.speech.speakers_per_split < spec.mixture.speakers
    ):
        yield _err(
            ("corpora", "speech", "speakers_per_split"),
            f"each group needs {spec.mixture.speakers} different speakers but a split has "
            f"only {c.speech.speakers_per_split}",
        )


def _check_mixture(spec: DatasetSpec) -> Iterator[Problem]:
    m = spec.mixture
    for k, task in enumerate(m.tasks):
        path = ("mixture", "tasks", k)
        if isinstance(task, SeparationTaskSpec) and task.speakers > m.speakers:
            yield _err(
                (*path, "speakers"),
                f"needs {task.speakers} speakers but a group has mixture.speakers = {m.speakers}",
            )
        if isinstance(task, EnhancementTaskSpec | SeparationTaskSpec):
            needs = {
                "noise": ["noise"],
                "music": ["music"],
                "both": ["noise", "music"],
                "none": [],
            }[task.background]
            for kind in needs:
                if getattr(spec.corpora, kind) is None:
                    yield _err(
                        (*path, "background"),
                        f"{task.background!r} needs a {kind} corpus: add corpora.{kind}",
                    )
                elif getattr(m, f"{kind}_clips")[1] == 0:
                    yield _err(
                        (*path, "background"),
                        f"{task.background!r} needs {kind} but mixture.{kind}_clips is 0",
                    )
    shortest_speech = m.utterances_per_speaker[0] * m.utterance_gap_s[0]
    if shortest_speech >= m.duration_s:
        yield _err(
            ("mixture", "utterance_gap_s"),
            f"{m.utterances_per_speaker[0]} utterances with at least "
            f"{m.utterance_gap_s[0]:g} s of silence each cannot fit in "
            f"{m.duration_s:g} s",
        )
    if m.utterance_gap_s[1] >= m.duration_s:
        # arrange_speech draws a gap before each speaker's first utterance too: one drawn this
        # long leaves no room for any utterance, and the arrange step fails (issue 28 item 11)
        yield _err(
            ("mixture", "utterance_gap_s"),
            f"a gap drawn up to {m.utterance_gap_s[1]:g} s before a speaker's first utterance "
            f"leaves no room for it in the {m.duration_s:g} s clip (the build's arrange step "
            f"fails on such a draw); expected an upper bound below mixture.duration_s minus "
            f"the shortest utterance, got {list(m.utterance_gap_s)}",
        )
    for kind in ("noise", "music"):
        field = getattr(m, f"{kind}_field")
        if field.diffuse and (getattr(spec.corpora, kind) is None
                              or getattr(m, f"{kind}_clips")[1] == 0):
            yield _warn(
                ("mixture", f"{kind}_field"),
                f"{field.field!r} has no effect: a group has no {kind} track (corpora.{kind} "
                f"and a non-zero mixture.{kind}_clips make one)",
            )
    if m.interpolation not in ("auto", "sample_crossfade") and isinstance(
            spec.trajectory, StaticTrajectorySpec):
        yield _warn(
            ("mixture", "interpolation"), f"{m.interpolation!r} has no effect: sources are static"
        )


def check_directivity(spec: DatasetSpec) -> Iterator[Problem]:
    """Head turns are heard only along the exact paths: RIRs at points cannot follow them
    (a standing source has one RIR; a walking one passes a point every 0.17–0.25 s, and the
    rir step of a static microphone does not know when), so any other rendering would leave
    them out without a word (docs/guide/directivity.md)."""
    for role in ("speech", "noise", "music"):
        d = spec.directivity.role(role)
        if d.head_turn is None:
            continue
        path = ("directivity", role, "head_turn")
        if d.is_omni:
            yield _warn(path, f"has no effect: directivity.{role}.pattern is 'omni' (it "
                              "radiates the same whichever way it faces)")
        elif spec.mixture.rendering() != "paths":
            yield _err(path, "head turns are rendered along the exact paths: expected "
                             "mixture.interpolation 'paths' or 'auto', got "
                             f"{spec.mixture.interpolation!r} (RIRs at points face as "
                             f"directivity.{role}.facing says and cannot follow a turn); set "
                             "mixture.interpolation: paths or remove the head_turn")


def _check_acoustics(spec: DatasetSpec) -> Iterator[Problem]:
    a = spec.acoustics
    if a.bands_hz != "auto":
        allowed = bands_below_nyquist(spec.sample_rate_hz)
        for k, band in enumerate(a.bands_hz):
            if float(band) not in allowed:
                yield _err(
                    ("acoustics", "bands_hz", k),
                    f"the {band} Hz band reaches above Nyquist "
                    f"({spec.sample_rate_hz / 2:g} Hz at sample_rate_hz = "
                    f"{spec.sample_rate_hz}); remove it or raise the sample rate",
                )
        if len(set(a.bands_hz)) != len(a.bands_hz):
            yield _err(("acoustics", "bands_hz"), "bands are listed more than once")
    if a.rays < MIN_RAYS_WITHOUT_WARNING:
        yield _warn(
            ("acoustics", "rays"),
            f"{a.rays} rays leave audible Monte-Carlo noise in the late reverberation; "
            f"use at least {MIN_RAYS_WITHOUT_WARNING}",
        )
    if a.roulette_db >= a.energy_threshold_db:
        yield _warn(
            ("acoustics", "roulette_db"),
            f"roulette_db = {a.roulette_db:g} is not below energy_threshold_db = "
            f"{a.energy_threshold_db:g}: rays stop at the threshold before the roulette starts, "
            "so it has no effect; lower it (the default is 30) or set it to 0",
        )
    if a.horizontal_guiding > MAX_GUIDING_WITHOUT_WARNING:
        yield _warn(
            ("acoustics", "horizontal_guiding"),
            f"horizontal_guiding = {a.horizontal_guiding:g} leaves too few plain directions: "
            "rays just outside the bands then carry large weights and one RIR's decay "
            "becomes erratic (in a furnished apartment 0.7 gave a 29 % worst-seed T30 error "
            "where 0.5 gave 4.6 %, bench/RESULTS.md); use at most "
            f"{MAX_GUIDING_WITHOUT_WARNING:g}",
        )
    if a.simplify_tolerance_m > MAX_SIMPLIFY_WITHOUT_WARNING_M:
        yield _warn(
            ("acoustics", "simplify_tolerance_m"),
            f"simplify_tolerance_m = {a.simplify_tolerance_m:g} m lets the traced surfaces "
            f"move by more than {100 * MAX_SIMPLIFY_WITHOUT_WARNING_M:g} cm, a quarter of the "
            "wavelength at 4 kHz (8.6 cm): bumps and recesses that shape the highest bands "
            f"may be flattened; use at most {MAX_SIMPLIFY_WITHOUT_WARNING_M:g} (scan noise "
            "is rarely larger)",
        )


def _outside(path: str) -> bool:
    """Whether a spec-relative path leaves the spec's folder (absolute, or up through '..')."""
    norm = posixpath.normpath(path.replace("\\", "/"))
    return posixpath.isabs(norm) or norm == ".." or norm.startswith("../") or (
        len(norm) > 1 and norm[1] == ":")  # a Windows drive


def _resolves_outside(path: str, base_dir: Path) -> Path | None:
    """Where a spec-relative path really leads when a symbolic link on the way takes it out of
    the spec's folder (None if it stays inside). The path text alone cannot tell."""
    try:
        base = base_dir.resolve()
        real = (base_dir / path).resolve()
    except (OSError, RuntimeError):  # a symlink loop: not a folder anything can be written to
        return base_dir / path
    return None if real == base or real.is_relative_to(base) else real


def _check_output_folders(spec: DatasetSpec, cli_outputs: Collection[str],
                          base_dir: Path | None = None) -> Iterator[Problem]:
    o = spec.outputs
    for name in ("dir", "store_dir"):
        value = getattr(o, name)
        if name in cli_outputs or o.allow_outside_spec_folder:
            continue
        flag = "--output-dir" if name == "dir" else "--store-dir"
        hint = (f"a spec chooses where it writes only inside its own folder: pass {flag} DIR "
                "to `sonicspec build`, or set outputs.allow_outside_spec_folder: true")
        if _outside(value):
            yield _err(("outputs", name),
                       f"expected a folder inside the spec's folder, got {value!r}; {hint}")
            continue
        real = None if base_dir is None else _resolves_outside(value, base_dir)
        if real is not None:
            yield _err(("outputs", name),
                       f"expected a folder inside the spec's folder, got {value!r}, which is a "
                       f"symbolic link (or lies under one) to {real}; {hint}")
    if not cli_outputs:
        a = posixpath.normpath(o.dir.replace("\\", "/"))
        b = posixpath.normpath(o.store_dir.replace("\\", "/"))
        if a != b and (b.startswith(a + "/") or a.startswith(b + "/")):
            yield _err(("outputs", "store_dir"),
                       f"the store ({o.store_dir!r}) and the dataset folder ({o.dir!r}) must "
                       "not lie inside one another")


def _check_outputs(spec: DatasetSpec) -> Iterator[Problem]:
    o = spec.outputs
    if o.audio_format == "flac" and o.subtype == "FLOAT":
        yield _err(
            ("outputs", "subtype"),
            "FLAC cannot store FLOAT samples; use PCM_16 or PCM_24, or audio_format: wav",
        )
    if Path(o.dir) == Path(o.store_dir):
        yield _err(("outputs", "store_dir"), "must differ from outputs.dir")
    if o.bits is not None and (o.scale != "per_file" or o.subtype == "FLOAT"
                               or o.bits > (16 if o.subtype == "PCM_16" else 24)):
        yield _err(("outputs", "bits"),
                   f"expected bits only with scale: per_file and a PCM subtype holding them "
                   f"(PCM_16: 16, PCM_24: 16..24), got bits {o.bits} with scale {o.scale}, "
                   f"subtype {o.subtype}")
    if (spec.mixture.loudness.peak_limit_dbfs is None and o.subtype != "FLOAT"
            and o.scale != "per_file"):
        yield _err(("mixture", "loudness", "peak_limit_dbfs"),
                   f"null keeps absolute levels, which may pass 0 dBFS: {o.subtype} would clip "
                   "them; record a scale per file (outputs.scale: per_file), write float WAV "
                   "(outputs.audio_format: wav, subtype: FLOAT) or set a limit")
    if channel_count(spec.microphone) > 8 and o.audio_format == "flac":
        yield _err(
            ("outputs", "audio_format"),
            f"FLAC holds at most 8 channels and the microphone renders "
            f"{channel_count(spec.microphone)}; use audio_format: wav",
        )


def _check_trajectory(spec: DatasetSpec) -> Iterator[Problem]:
    if (not isinstance(spec.microphone.trajectory, StaticTrajectorySpec)
            and spec.placement.mic_position_m is not None):
        start = (spec.microphone.trajectory.start_m
                 if isinstance(spec.microphone.trajectory, LineTrajectorySpec)
                 else spec.microphone.trajectory.points_m[0])
        if math.dist(start, spec.placement.mic_position_m) > 1e-6:
            yield _err(("placement", "mic_position_m"),
                       f"{list(spec.placement.mic_position_m)} is not where the moving "
                       f"microphone starts ({list(start)}, microphone.trajectory); leave it "
                       "out (a moving microphone is placed at its start)")
    for prefix, traj in (
        (("trajectory",), spec.trajectory),
        (("microphone", "trajectory"), spec.microphone.trajectory),
    ):
        if isinstance(traj, WaypointsTrajectorySpec):
            for k in range(1, len(traj.points_m)):
                if math.dist(traj.points_m[k - 1], traj.points_m[k]) < 1e-6:
                    yield _err(
                        (*prefix, "points_m", k),
                        f"repeats waypoint {k - 1}; consecutive points must differ",
                    )
        if (
            isinstance(traj, LineTrajectorySpec)
            and traj.start_m is not None
            and traj.end_m is not None
            and math.dist(traj.start_m, traj.end_m) < 1e-6
        ):
            yield _err((*prefix, "end_m"), "equals start_m; a line needs two distinct points")


def _check_heights_and_distances(spec: DatasetSpec) -> Iterator[Problem]:
    p = spec.placement
    for _, scene in _procedural(spec):
        h = scene.height()
        poly = scene.floor_polygon()
        if spec.microphone.height_m >= h:
            yield _err(
                ("microphone", "height_m"),
                f"{spec.microphone.height_m:g} m is not below the ceiling of scene "
                f"{scene.id!r} ({h:g} m)",
            )
        for name in ("source_height_m", "noise_height_m"):
            if getattr(p, name)[1] >= h:
                yield _err(
                    ("placement", name),
                    f"up to {getattr(p, name)[1]:g} m is not below the ceiling of scene "
                    f"{scene.id!r} ({h:g} m)",
                )
        xs, ys = [q[0] for q in poly], [q[1] for q in poly]
        reach = math.hypot(max(xs) - min(xs), max(ys) - min(ys))
        reach = math.hypot(reach, h)
        for name in (
            "source_start_distance_m",
            "source_end_distance_m",
            "source_travel_distance_m",
            "noise_distance_m",
            "music_distance_m",
        ):
            low = getattr(p, name)[0]
            if low > reach:
                yield _err(
                    ("placement", name),
                    f"at least {low:g} m cannot fit in scene {scene.id!r}, whose largest "
                    f"distance is {reach:.2f} m",
                )


def check_files(spec: DatasetSpec, base_dir: Path) -> list[Problem]:
    """Problems with files and folders the spec refers to, resolved against ``base_dir``."""
    problems: list[Problem] = []

    def exists(path: tuple, rel: str, what: str, folder: bool = False) -> bool:
        full = base_dir / rel
        ok = full.is_dir() if folder else full.exists()
        if not ok:
            problems.append(_err(path, f"{what} {str(full)!r} does not exist"))
        return ok

    for i, scene in enumerate(spec.scenes):
        if isinstance(scene, MeshSceneSpec):
            if glob.has_magic(scene.path):
                if not glob.glob(str(base_dir / scene.path)):
                    problems.append(
                        _err(
                            ("scenes", i, "path"),
                            f"glob {scene.path!r} matches no file under {str(base_dir)!r}",
                        )
                    )
            else:
                exists(("scenes", i, "path"), scene.path, "mesh file")
        for j, ob in enumerate(scene.obstacles):
            if isinstance(ob, MeshObstacleSpec):
                exists(("scenes", i, "obstacles", j, "path"), ob.path, "mesh file")
    problems.extend(_pinned_scene_problems(spec, base_dir))
    hrtf = getattr(spec.microphone, "hrtf", None)
    if hrtf is not None and hrtf.kind == "sofa":
        exists(("microphone", "hrtf", "path"), hrtf.path, "SOFA file")
    for kind in ("speech", "noise", "music"):
        corpus = getattr(spec.corpora, kind)
        path = ("corpora", kind)
        if corpus is None or not hasattr(corpus, "root"):
            continue
        if not exists((*path, "root"), corpus.root, "corpus folder", folder=True):
            continue
        root = corpus.root
        if isinstance(corpus, LibriSpeechCorpusSpec):
            # Only the subsets of the spec's splits are read (README: no val split, no
            # dev-clean needed).
            for split, subsets in corpus.subsets.items():
                for sub in subsets if split in spec.splits else ():
                    exists(
                        (*path, "subsets", split),
                        f"{root}/{sub}",
                        "LibriSpeech subset",
                        folder=True,
                    )
        elif isinstance(corpus, Fsd50kCorpusSpec):
            for part in ("FSD50K.dev_audio", "FSD50K.eval_audio", "FSD50K.ground_truth"):
                exists((*path, "root"), f"{root}/{part}", "FSD50K folder", folder=True)
        elif isinstance(corpus, FmaCorpusSpec):
            exists((*path, "size"), f"{root}/fma_{corpus.size}", "FMA audio folder", folder=True)
            exists((*path, "root"), f"{root}/fma_metadata/tracks.csv", "FMA metadata file")
    return problems


def _pinned_scene_problems(spec: DatasetSpec, base_dir: Path) -> list[Problem]:
    """Scene ids a split writes out (``mp3d/<building>``) that no file of their mesh glob
    gives: a pinned scene list that names a scan the data does not have."""
    families: dict[str, list[str]] = {}
    for scene in spec.scenes:
        if isinstance(scene, MeshSceneSpec) and glob.has_magic(scene.path):
            files = [Path(p) for p in glob.glob(str(base_dir / scene.path))]
            families[scene.id] = sorted(f"{scene.id}/{f.stem}" for f in files if f.is_file())
    problems = []
    for name, split in spec.splits.items():
        for k, pattern in enumerate(split.scenes):
            family = pattern.split("/")[0]
            if glob.has_magic(pattern) or "/" not in pattern or family not in families:
                continue
            if families[family] and pattern not in families[family]:
                problems.append(_err(
                    ("splits", name, "scenes", k),
                    f"no scene {pattern!r}: glob of scene {family!r} gives no such file"
                    + did_you_mean(pattern, families[family])))
    return problems


def _check_augmentation(spec: DatasetSpec) -> Iterator[Problem]:
    """MP3 bit rates the dataset's rate can be coded at; resampling that would do nothing."""
    if spec.augmentation is None:
        return
    rate = spec.sample_rate_hz
    where: list[tuple[tuple, object]] = []
    for i, e in enumerate(spec.augmentation.effects):
        where.append((("augmentation", "effects", i), e))
        if e.kind == "one_of":
            where += [(("augmentation", "effects", i, "effects", j), inner)
                      for j, inner in enumerate(e.effects)]
    allowed = mp3_bitrates_at(rate)
    for path, e in where:
        kind = getattr(e, "kind", None)
        if kind == "mp3":
            for j, b in enumerate(e.bitrate_kbps):
                if b not in allowed:
                    yield _err((*path, "bitrate_kbps", j),
                               f"expected an MP3 bit rate at sample_rate_hz {rate} "
                               f"({', '.join(map(str, allowed))} kbit/s), got {b}")
        elif kind == "resample":
            for j, r in enumerate(e.rate_hz):
                if r >= rate:
                    yield _warn((*path, "rate_hz", j),
                                f"{r} Hz is not below sample_rate_hz ({rate}): resampling "
                                "through it does nothing")
