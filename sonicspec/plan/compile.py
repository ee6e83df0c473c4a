"""Spec -> Plan: expand scenes and splits, assign groups to scenes, cut shards, key every job.

Everything here is deterministic: the same spec and the same input files give the same plan,
so ``sonicspec plan`` twice prints the same keys. Files enter keys by content (SHA-256 of a mesh,
a listing of names and sizes for a corpus folder), never by path or modification time, so a
spec moved to another machine with the same data keeps its keys.

Groups are the unit of content: every random draw about a group is seeded by the spec seed and
the group id (``<split>/<index>``), not by the shard it lands in, so changing
``groups_per_shard`` regroups work without changing a single sample.
"""

from __future__ import annotations

import fnmatch
import glob
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sonicspec.atomic import write_text
from sonicspec.audio.corpora import folder_speakers, librispeech_speakers
from sonicspec.errors import CompileError, SonicspecError
from sonicspec.hashing import canonical_json, file_sha256, rng_for, sha256_hex, shared
from sonicspec.plan.model import Job, Plan
from sonicspec.plan.params import (
    ARRANGEMENT_FIELDS,
    MaterialTable,
    OutputsParams,
    without_omitted,
)
from sonicspec.shares import split_shares
from sonicspec.spec.checks import check_directivity
from sonicspec.spec.corpora import GeneratedSpeechSpec, LibriSpeechCorpusSpec
from sonicspec.spec.dataset import DatasetSpec
from sonicspec.spec.load import LoadedSpec, format_path
from sonicspec.spec.scene import MeshObstacleSpec, MeshSceneSpec
from sonicspec.spec.splits import EACH_SPEAKER_PER_SCENE, MAX_GROUPS
from sonicspec.spec.trajectory import StaticTrajectorySpec


@dataclass(frozen=True)
class SceneEntry:
    """One concrete scene after glob expansion."""

    id: str
    index: int  # position in spec.scenes
    file: Path | None  # the mesh file of a mesh scene


def _dump(model: Any) -> Any:
    return model.model_dump(mode="json")


class FileDigests:
    """SHA-256 of files, cached by (path, size, mtime) so re-planning does not re-read them."""

    def __init__(self, cache_file: Path | None = None) -> None:
        self.cache_file = cache_file
        self._cache: dict[str, str] = {}
        self._dirty = False
        if cache_file is not None and cache_file.is_file():
            try:
                self._cache = json.loads(cache_file.read_text())
            except ValueError:
                self._cache = {}

    def file(self, path: Path) -> str:
        try:
            st = path.stat()
        except FileNotFoundError:
            raise CompileError(f"{path}: file does not exist") from None
        token = f"{path.resolve()}|{st.st_size}|{st.st_mtime_ns}"
        if token not in self._cache:
            self._cache[token] = file_sha256(path)
            self._dirty = True
        return self._cache[token]

    def mesh(self, path: Path) -> str:
        """:meth:`file` of a scene file, refused first if it is beyond the mesh size bound
        (hashing a 2 GB file the mesh step would refuse costs half a minute)."""
        from sonicspec.errors import GeometryError
        from sonicspec.geometry.io import check_mesh_size

        try:
            check_mesh_size(path)
        except FileNotFoundError:
            raise CompileError(f"{path}: file does not exist") from None
        except GeometryError as exc:
            raise CompileError(str(exc)) from None
        return self.file(path)

    @staticmethod
    def folder(path: Path) -> str:
        """Digest of a folder's file names and sizes (portable across copies)."""
        if not path.is_dir():
            raise CompileError(f"{path}: corpus folder does not exist")
        entries = []
        for root, dirs, files in os.walk(path):
            dirs.sort()
            for name in sorted(files):
                full = Path(root) / name
                entries.append(f"{full.relative_to(path).as_posix()}|{full.stat().st_size}")
        return sha256_hex("\n".join(entries))

    def save(self) -> None:
        if self.cache_file is None or not self._dirty:
            return
        write_text(self.cache_file, json.dumps(self._cache, sort_keys=True))


def expand_scenes(spec: DatasetSpec, base_dir: Path) -> list[SceneEntry]:
    """Concrete scenes: one per procedural scene, one per file a mesh glob matches."""
    out: list[SceneEntry] = []
    for i, scene in enumerate(spec.scenes):
        if isinstance(scene, MeshSceneSpec):
            pattern = str(base_dir / scene.path)
            if glob.has_magic(scene.path):
                files = sorted(Path(p) for p in glob.glob(pattern) if Path(p).is_file())
                if not files:
                    raise CompileError(
                        f"scenes[{i}].path: glob {scene.path!r} matches no file under {base_dir}"
                    )
                out.extend(SceneEntry(f"{scene.id}/{f.stem}", i, f) for f in files)
            else:
                f = Path(pattern)
                if not f.is_file():
                    raise CompileError(f"scenes[{i}].path: mesh file {f} does not exist")
                out.append(SceneEntry(scene.id, i, f))
        else:
            out.append(SceneEntry(scene.id, i, None))
    ids = [e.id for e in out]
    dupes = sorted({x for x in ids if ids.count(x) > 1})
    if dupes:
        raise CompileError(f"scenes: ids {dupes} occur twice after expanding globs")
    return out


def assign_split_scenes(spec: DatasetSpec, entries: list[SceneEntry]) -> dict[str, list[str]]:
    """Which concrete scenes each split uses (disjoint; ``scene_count`` draws from a pool)."""
    ids = [e.id for e in entries]
    taken: set[str] = set()
    out: dict[str, list[str]] = {}
    for name, split in spec.splits.items():
        matched: list[str] = []
        for k, pattern in enumerate(split.scenes):
            hits = [
                i
                for i in ids
                if fnmatch.fnmatchcase(i, pattern) or (pattern == i.split("/")[0] and "/" in i)
            ]
            if not hits:
                raise CompileError(f"splits.{name}.scenes[{k}]: {pattern!r} matches no scene")
            matched.extend(h for h in hits if h not in matched)
        if split.scene_count is not None:
            pool = sorted(m for m in matched if m not in taken)
            if len(pool) < split.scene_count:
                verb = "is" if len(pool) == 1 else "are"
                left = (f"only {len(pool)} of the scenes it matches {verb} not taken by "
                        "earlier splits")
                raise CompileError(
                    f"splits.{name}.scene_count: asks for {split.scene_count} scenes, but "
                    f"{left} ({len(matched)} matched in all); add scenes or lower "
                    f"scene_count"
                )
            order = rng_for(spec.seed, "split-scenes", name).permutation(len(pool))
            chosen = sorted(pool[i] for i in order[: split.scene_count])
        else:
            chosen = sorted(matched)
            shared = sorted(set(chosen) & taken)
            if shared:
                raise CompileError(
                    f"splits.{name}.scenes: scenes {shared} are used by another "
                    "split; splits must be disjoint"
                )
        taken.update(chosen)
        out[name] = chosen
    return out


@dataclass(frozen=True)
class SplitLayout:
    """How big a split is once its scenes are expanded and, for a split composed per speaker
    and scene, its speakers counted."""

    scenes: tuple[str, ...]
    groups: int
    speakers: int | None
    """Speakers of the split: counted for ``each_speaker_per_scene`` splits, and for every
    split when asked (the summary); None when not counted."""
    per_speaker: bool
    """Composed per speaker and scene (``groups: each_speaker_per_scene``)."""


def split_speakers(spec: DatasetSpec, base_dir: Path, splits: list[str]) -> dict[str, int]:
    """How many speakers the speech corpus gives each of ``splits``, from folder names alone
    (the corpus is indexed later, by its job; the arrange stage checks the index agrees)."""
    corpus = spec.corpora.speech
    try:
        if isinstance(corpus, GeneratedSpeechSpec):
            return {s: corpus.speakers_per_split for s in splits}
        root = base_dir / corpus.root
        if not root.is_dir():
            raise CompileError(f"corpora.speech.root: corpus folder {root} does not exist")
        if isinstance(corpus, LibriSpeechCorpusSpec):
            found = librispeech_speakers(root, {s: corpus.subsets[s] for s in splits
                                                if s in corpus.subsets})
        else:
            shares = split_shares(corpus.split_ratios, list(spec.splits))
            # The seed the corpus job's ratio split uses (its rng: "corpus", role).
            found = folder_speakers(root, corpus.extensions, shares,
                                    rng_for(spec.seed, "corpus", "speech"))
    except SonicspecError as err:
        if isinstance(err, CompileError):
            raise
        raise CompileError(f"corpora.speech: {err}") from None
    return {s: len(found.get(s, [])) for s in splits}


def split_layouts(spec: DatasetSpec, entries: list[SceneEntry], base_dir: Path, *,
                  count_speakers: bool = False) -> dict[str, SplitLayout]:
    """Scenes, groups and speakers of every split (speakers: of the splits composed per
    speaker and scene, or of all with ``count_speakers``).

    ``each_speaker_per_scene``: floor(speakers / mixture.speakers) groups in every scene;
    the speakers left over (fewer than a group) sit that scene out.
    """
    scenes = assign_split_scenes(spec, entries)
    per_speaker = [n for n, s in spec.splits.items() if s.groups == EACH_SPEAKER_PER_SCENE]
    wanted = list(spec.splits) if count_speakers else per_speaker
    counts = split_speakers(spec, base_dir, wanted) if wanted else {}
    out: dict[str, SplitLayout] = {}
    for name, split in spec.splits.items():
        if name in per_speaker:
            per_scene = counts[name] // spec.mixture.speakers
            if per_scene == 0:
                raise CompileError(
                    f"splits.{name}.groups: each_speaker_per_scene needs at least "
                    f"{spec.mixture.speakers} speakers (mixture.speakers), corpora.speech gives "
                    f"split '{name}' {counts[name]}")
            out[name] = SplitLayout(tuple(scenes[name]), per_scene * len(scenes[name]),
                                    counts[name], True)
        else:
            out[name] = SplitLayout(tuple(scenes[name]), int(split.groups), counts.get(name),
                                    False)
    total = sum(x.groups for x in out.values())
    if total > MAX_GROUPS:
        raise CompileError(
            f"splits: expected at most {MAX_GROUPS:,} groups in all splits together, got "
            f"{total:,} (" + ", ".join(f"{k}: {x.groups:,}" for k, x in out.items()) + ")")
    return out


def layouts_of(loaded: LoadedSpec, *, count_speakers: bool = True) -> dict[str, SplitLayout]:
    """Every split's layout for ``loaded`` (scene globs expanded, speaker folders counted; no
    file is hashed), for ``sonicspec plan --summary``."""
    base = loaded.base_dir.resolve()
    return split_layouts(loaded.spec, expand_scenes(loaded.spec, base), base,
                         count_speakers=count_speakers)


def group_scenes(spec: DatasetSpec, split: str, scenes: list[str] | tuple[str, ...],
                 groups: int) -> list[str]:
    """The scene of every one of ``groups`` groups of ``split``: a seeded permutation of the
    scenes, repeated (balanced).

    Group ``i`` keeps its scene when the split's group count changes; in a split composed per
    speaker and scene, group ``i`` is slot ``i // len(scenes)`` of its scene (its speakers
    are that slot of the scene's speaker shuffle), so it keeps scene and slot when the number
    of speakers changes.
    """
    order = rng_for(spec.seed, "group-scenes", split).permutation(len(scenes))
    return [scenes[order[i % len(scenes)]] for i in range(groups)]


def _mesh_params(
    spec: DatasetSpec, entry: SceneEntry, digests: FileDigests, base_dir: Path
) -> tuple[dict[str, Any], dict[str, str]]:
    scene = spec.scenes[entry.index]
    dumped = _dump(scene)
    dumped.pop("id", None)
    files: dict[str, str] = {}
    paths: dict[str, str] = {}
    if isinstance(scene, MeshSceneSpec) and entry.file is not None:
        dumped.pop("path", None)
        files["mesh"] = digests.mesh(entry.file)
        paths["mesh"] = str(entry.file)
        stem = entry.file.with_suffix("")
        for role, extra in (
            ("semantic", Path(f"{stem}_semantic.ply")),
            ("house", stem.with_suffix(".house")),
        ):
            if scene.format != "plain" and extra.is_file():
                files[role] = digests.mesh(extra)
                paths[role] = str(extra)
        if scene.format == "matterport" and "semantic" not in files:
            raise CompileError(
                f"scenes[{entry.index}]: format 'matterport' needs "
                f"{stem.name}_semantic.ply beside {entry.file.name}"
            )
    for j, ob in enumerate(scene.obstacles):
        if isinstance(ob, MeshObstacleSpec):
            files[f"obstacle{j}"] = digests.mesh(base_dir / ob.path)
            paths[f"obstacle{j}"] = str(base_dir / ob.path)
    params: dict[str, Any] = {"scene": dumped, "files": files, "scene_id": entry.id}
    if isinstance(scene, MeshSceneSpec):
        # Faces of a scan get materials from their labels: the library's rule, overridden by
        # the spec's global map and then by the scene's own.
        params["library"] = spec.materials.library
        params["label_materials"] = {**spec.materials.label_materials, **scene.label_materials}
        if entry.file is not None and entry.file.suffix.lower() == ".obj":
            # An obj file's lone object keeps its name and group-only files are labelled by
            # group (trimesh drops both): only obj scenes' keys carry the flag, so only their
            # meshes are made again.
            params["obj_labels"] = True
    return params, paths


def _corpus_params(
    spec: DatasetSpec, role: str, base_dir: Path
) -> tuple[dict[str, Any], dict[str, str]] | None:
    corpus = getattr(spec.corpora, role)
    if corpus is None:
        return None
    paths = {"cache": str((base_dir / spec.corpora.cache_dir).resolve())}
    dumped = _dump(corpus)
    params: dict[str, Any] = {
        "role": role,
        "corpus": dumped,
        "sample_rate_hz": spec.sample_rate_hz,
        "seed": spec.seed,
        "splits": list(spec.splits),
    }
    if "root" in dumped:
        root = base_dir / corpus.root
        dumped.pop("root")
        if not root.is_dir():
            raise CompileError(f"corpora.{role}.root: corpus folder {root} does not exist")
        params["listing"] = FileDigests.folder(root)
        paths["root"] = str(root.resolve())
    return params, paths


def _hrtf_file(spec: DatasetSpec, base_dir: Path, digests: FileDigests
               ) -> tuple[dict[str, str], dict[str, str]]:
    """The SOFA file of a binaural microphone: (digest by role, path by role), else empty."""
    hrtf = getattr(spec.microphone, "hrtf", None)
    if hrtf is None or hrtf.kind != "sofa":
        return {}, {}
    path = base_dir / hrtf.path
    if not path.is_file():
        raise CompileError(f"microphone.hrtf.path: SOFA file {path} does not exist")
    return {"hrtf": digests.file(path)}, {"hrtf": str(path)}


def _directivity(spec: DatasetSpec, base_dir: Path, digests: FileDigests
                 ) -> tuple[dict[str, Any], dict[str, str], dict[str, str]]:
    """The rir step's ``directivity`` param when some source is not omnidirectional (else
    nothing), and its SOFA files: (params, digest by role, path by role)."""
    if spec.directivity.is_omni:
        return {}, {}, {}
    for problem in check_directivity(spec):  # validate's check, for a spec made in Python
        if problem.severity == "error":
            raise CompileError(f"{format_path(problem.path)}: {problem.message}")
    files, paths = {}, {}
    for role in ("speech", "noise", "music"):
        d = spec.directivity.role(role)
        if d.pattern != "sofa":
            continue
        path = base_dir / d.sofa_path
        if not path.is_file():
            raise CompileError(f"directivity.{role}.sofa_path: SOFA file {path} does not exist")
        files[f"directivity_{role}"] = digests.file(path)
        paths[f"directivity_{role}"] = str(path)
    return {"directivity": _dump(spec.directivity)}, files, paths


def _impulse_response_files(spec: DatasetSpec, base_dir: Path, digests: FileDigests
                            ) -> tuple[dict[str, str], dict[str, str]]:
    """The impulse-response files of ``augmentation``: (digest by file as written, path by
    file as written), else empty."""
    if spec.augmentation is None:
        return {}, {}
    effects = [*spec.augmentation.effects]
    effects += [e for o in effects if o.kind == "one_of" for e in o.effects]
    files: dict[str, str] = {}
    paths: dict[str, str] = {}
    for i, effect in enumerate(effects):
        for name in getattr(effect, "files", None) or ():
            path = base_dir / name
            if not path.is_file():
                raise CompileError(f"augmentation.effects: impulse-response file {path} "
                                   f"(effect {i}, {name!r}) does not exist")
            files[name], paths[name] = digests.file(path), str(path)
    return files, paths


def scene_jobs(spec: DatasetSpec, entries: list[SceneEntry], base_dir: Path,
               digests: FileDigests) -> list[tuple[SceneEntry, Job, Job]]:
    """The ``mesh`` and ``navigation`` jobs of every concrete scene (no corpus is read)."""
    out = []
    for entry in entries:
        params, paths = _mesh_params(spec, entry, digests, base_dir)
        mesh = Job("mesh", params, (), f"mesh {entry.id}", paths)
        nav = Job("navigation", {
            "walker_radius_m": spec.placement.walker_radius_m,
            "walker_height_m": spec.placement.walker_height_m,
        }, (mesh.key,), f"navigation {entry.id}")
        out.append((entry, mesh, nav))
    return out


def _shards(groups: list[str], size: int) -> list[list[str]]:
    return [groups[i : i + size] for i in range(0, len(groups), size)]


def compile_spec(loaded: LoadedSpec, *, cache: bool = True, output_dir: str | Path | None = None,
                 store_dir: str | Path | None = None) -> Plan:
    """The plan of ``loaded``; :class:`CompileError` when the data it needs is not there.

    ``output_dir`` and ``store_dir`` replace the spec's folders (``sonicspec build
    --output-dir``); no content key depends on where the folders are.
    """
    spec: DatasetSpec = loaded.spec
    base = loaded.base_dir.resolve()
    store_dir = Path(store_dir or base / spec.outputs.store_dir).resolve()
    output_dir = Path(output_dir or base / spec.outputs.dir).resolve()
    digests = FileDigests(store_dir / "cache" / "file-digests.json" if cache else None)

    jobs: list[Job] = []

    corpus_keys: dict[str, str] = {}
    for role in ("speech", "noise", "music"):
        found = _corpus_params(spec, role, base)
        if found is not None:
            job = Job("corpus", found[0], (), f"corpus {role}", found[1])
            jobs.append(job)
            corpus_keys[role] = job.key

    entries = expand_scenes(spec, base)
    mesh_keys: dict[str, str] = {}
    nav_keys: dict[str, str] = {}
    for entry, mesh, nav in scene_jobs(spec, entries, base, digests):
        jobs.extend([mesh, nav])
        mesh_keys[entry.id], nav_keys[entry.id] = mesh.key, nav.key
    rir_files, rir_paths = _hrtf_file(spec, base, digests)
    directivity, source_files, source_paths = _directivity(spec, base, digests)
    rir_files, rir_paths = {**rir_files, **source_files}, {**rir_paths, **source_paths}
    ir_files, ir_paths = _impulse_response_files(spec, base, digests)
    digests.save()
    augmentation = (shared(_dump(spec.augmentation)) if spec.augmentation is not None
                    else None)

    layouts = split_layouts(spec, entries, base)
    # Sub-dicts every shard's jobs repeat are made once, with their canonical JSON, so keying
    # 10^6 groups does not encode them again per job (the keys are the same bytes).
    mic = shared(_dump(spec.microphone))
    mixture = _dump(spec.mixture)
    arrangement = shared({k: mixture[k] for k in ARRANGEMENT_FIELDS})
    placement_spec, trajectory = shared(_dump(spec.placement)), shared(_dump(spec.trajectory))
    acoustics = shared(_dump(spec.acoustics))
    materials = shared(without_omitted({k: v for k, v in _dump(spec.materials).items()
                                        if k in MaterialTable.model_fields},
                                       MaterialTable.omitted_when))
    loudness, tasks = shared(mixture["loudness"]), shared(mixture["tasks"])
    targets = shared(list(spec.mixture.targets))
    diffuse = {role: getattr(spec.mixture, f"{role}_field").model_dump(mode="json")
               for role in ("noise", "music") if getattr(spec.mixture, f"{role}_field").diffuse}
    backgrounds = {"backgrounds": shared(diffuse)} if diffuse else {}
    rir_files_shared = shared(rir_files)
    corpus_inputs = tuple(corpus_keys[r] for r in ("speech", "noise", "music") if r in corpus_keys)
    rendering = spec.mixture.rendering()  # `auto` resolved
    # A moving microphone: the rir step pairs source and microphone positions in time, so it
    # reads how the sources walk and the arrangement (when each speaks).
    walk = {} if isinstance(spec.microphone.trajectory, StaticTrajectorySpec) else {"walk": {
        "speed_m_s": getattr(spec.trajectory, "speed_m_s", None),
        "walk_span": getattr(spec.trajectory, "span", "speech")}}
    export_keys: list[str] = []
    outputs = _dump(spec.outputs)
    for k in ("dir", "store_dir", "allow_outside_spec_folder", "groups_per_shard", "report"):
        outputs.pop(k)  # where and how finely: no export writes other bytes for them
    # left out at their defaults, as OutputsParams serialises them: older exports keep their keys
    outputs = without_omitted(outputs, OutputsParams.omitted_when)
    outputs = shared(outputs)

    for split, layout in layouts.items():
        by_scene: dict[str, list[str]] = {}
        count = len(layout.scenes)
        for i, scene_id in enumerate(group_scenes(spec, split, layout.scenes, layout.groups)):
            by_scene.setdefault(scene_id, []).append(f"{split}/{i:06d}")
        for scene_id in sorted(by_scene):
            groups = by_scene[scene_id]
            for n, shard in enumerate(_shards(groups, spec.outputs.groups_per_shard)):
                tag = f"{split}/{scene_id}#{n}"
                common = {"groups": shared(shard), "split": split, "seed": spec.seed}
                composition = {} if not layout.per_speaker else {"composition": {
                    "scene_id": scene_id,
                    "slots": [int(g[len(split) + 1:]) // count for g in shard],
                    "speakers": layout.speakers,
                }}
                placement = Job(
                    "placement",
                    {
                        **common,
                        "scene_id": scene_id,
                        "placement": placement_spec,
                        "trajectory": trajectory,
                        "microphone": mic,
                        "speakers": spec.mixture.speakers,
                        "noise": "noise" in corpus_keys,
                        "music": "music" in corpus_keys,
                    },
                    (nav_keys[scene_id],),
                    f"placement {tag}",
                )
                arrange = Job(
                    "arrange",
                    {
                        **common,
                        "mixture": arrangement,
                        "sample_rate_hz": spec.sample_rate_hz,
                        **composition,
                    },
                    corpus_inputs,
                    f"arrange {tag}",
                )
                rir = Job(
                    "rir",
                    {
                        **common,
                        "acoustics": acoustics,
                        "materials": materials,
                        "microphone": mic,
                        "speed_of_sound_m_s": spec.speed_of_sound_m_s,
                        "sample_rate_hz": spec.sample_rate_hz,
                        "files": rir_files_shared,
                        "early_paths": rendering == "paths",
                        **walk,
                        **directivity,
                    },
                    (mesh_keys[scene_id], placement.key, *((arrange.key,) if walk else ())),
                    f"rir {tag}",
                    rir_paths,
                )
                render = Job(
                    "render",
                    {
                        **common,
                        "interpolation": rendering,
                        "targets": targets,
                        "sample_rate_hz": spec.sample_rate_hz,
                        "speed_m_s": getattr(spec.trajectory, "speed_m_s", None),
                        "walk_span": getattr(spec.trajectory, "span", "speech"),
                        "speed_of_sound_m_s": spec.speed_of_sound_m_s,
                        **backgrounds,
                    },
                    (rir.key, arrange.key, placement.key, *corpus_inputs),
                    f"render {tag}",
                    # a SOFA set hears the paths and the diffuse backgrounds
                    rir_paths if rendering == "paths" or backgrounds else {},
                )
                mix = Job(
                    "mix",
                    {
                        **common,
                        "loudness": loudness,
                        "tasks": tasks,
                        "speakers": spec.mixture.speakers,
                        "sample_rate_hz": spec.sample_rate_hz,
                        "binaural": spec.microphone.kind == "binaural",
                        "targets": targets,
                    },
                    (render.key,),
                    f"mix {tag}",
                )
                export = Job(
                    "export",
                    {
                        **common,
                        "outputs": outputs,
                        "output_dir": spec.outputs.dir,  # as written: keys do not depend on where
                        "sample_rate_hz": spec.sample_rate_hz,
                        "scene_id": scene_id,
                        **({"augmentation": augmentation, "impulse_responses": ir_files}
                           if augmentation is not None else {}),
                    },
                    (mix.key, render.key, rir.key, arrange.key, placement.key),
                    f"export {tag}",
                    ir_paths,
                )
                jobs.extend([placement, arrange, rir, render, mix, export])
                export_keys.append(export.key)

    spec_json = json.loads(loaded.spec.model_dump_json())
    jobs.append(
        Job(
            "dataset",
            {
                "spec": spec_json,
                "output_dir": spec.outputs.dir,  # as written: keys do not depend on where
                "manifests": list(spec.outputs.manifests),
                "splits": {s: layouts[s].groups for s in spec.splits},
            },
            (*corpus_inputs, *export_keys),  # corpora: their skipped files are reported
            "dataset",
        )
    )
    return Plan(
        name=spec.name,
        seed=spec.seed,
        store_dir=str(store_dir),
        output_dir=str(output_dir),
        spec_digest=sha256_hex(canonical_json(spec_json)),
        jobs=tuple(jobs),
    )


def recorded_keys(path: Path) -> dict[str, set[str]] | None:
    """Keys per step recorded in a plan file, without re-checking them.

    The last build's plan may come from another sonicspec version (a stage's version bumped,
    so its keys no longer re-hash): it still says which keys were built, which is all that
    "what changed since the last build" needs. None if the file is absent or unreadable.
    """
    try:
        data = json.loads(Path(path).read_text())
        out: dict[str, set[str]] = {}
        for item in data["jobs"]:
            out.setdefault(str(item["step"]), set()).add(str(item["key"]))
        return out
    except (OSError, ValueError, KeyError, TypeError):
        return None


def plan_changes(old: Plan | Mapping[str, set[str]] | None, new: Plan
                 ) -> dict[str, dict[str, int]]:
    """Per step: jobs kept, added and dropped relative to ``old`` (the last build's plan, or
    its keys per step)."""
    old_keys: Mapping[str, set[str]] = {}
    if isinstance(old, Plan):
        old_keys = {step: {j.key for j in jobs} for step, jobs in old.by_step().items()}
    elif old is not None:
        old_keys = old
    out = {}
    for step, jobs in new.by_step().items():
        keys = {j.key for j in jobs}
        before = old_keys.get(step, set())
        out[step] = {
            "kept": len(keys & before),
            "added": len(keys - before),
            "dropped": len(before - keys),
        }
    return out
