"""``sonicspec report``: one HTML page that shows what a dataset holds.

The page (``report.html``) is self-contained: its figures are SVG data URIs, its table and
scripts inline, nothing is fetched from the network. Group pages, one per sampled group, go in
a folder beside it (``report_files/groups/``) and play the dataset's own audio files through
relative links, so the report stays small however long the audio is; keep the report where it
was written relative to the dataset (the build writes it at the dataset folder's top).

Distributions come from the groups' metadata (no audio is decoded); scene geometry, repair
facts, material areas, build facts and the sampled groups' RIRs come from the artifact store
the dataset folder names (``.sonicspec-dataset.json``) when it is there.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec import __version__
from sonicspec.atomic import write_text
from sonicspec.errors import SonicspecError
from sonicspec.export import report_data as rd
from sonicspec.export import report_plots as plots
from sonicspec.export.checksums import REPORT_NAME

DEFAULT_GROUP_PAGES = 100
WALL_CUT_M = 1.0  # walls are cut 1 m above the floor, objects also at 0.25 m (as scene inspect)
OBJECT_CUT_M = 0.25


@dataclass(frozen=True)
class ReportResult:
    """What :func:`write_report` wrote and what it cost."""

    path: Path
    files_dir: Path
    groups: int
    group_pages: int
    seconds: float
    page_bytes: int
    total_bytes: int
    missing: list = field(default_factory=list)
    """Files the report lacks (``{"path", "problem"}``): it is incomplete when not empty."""


def files_dir_of(path: Path) -> Path:
    """The folder of group pages beside ``path``: ``report.html`` -> ``report_files``."""
    return path.with_name(f"{path.stem}_files")


def _environment():
    try:
        import jinja2
    except ImportError:
        raise SonicspecError("the report needs jinja2: pip install 'sonicspec[report]'") from None
    folder = resources.files("sonicspec") / "data" / "report"
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(folder)), autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True)
    env.filters["num"] = _fmt_num
    env.globals["zip"] = zip
    env.filters["tojson_script"] = _json_script
    return env


def _fmt_num(x: Any, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if isinstance(x, str):  # a rule, e.g. a split's groups: each_speaker_per_scene
        return x
    if isinstance(x, int):
        return f"{x:,}"
    return f"{x:.{digits}g}" if abs(x) < 1000 else f"{x:,.0f}"


def _json_script(value: Any) -> Any:
    """JSON safe inside ``<script type="application/json">`` (no ``</``)."""
    from markupsafe import Markup

    text = json.dumps(value, separators=(",", ":"), allow_nan=False)
    return Markup(text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026"))


def _split_order(info: rd.DatasetInfo, groups: Sequence[dict[str, Any]]) -> list[str]:
    present = {g["split"] for g in groups}
    order = [s for s in (info.spec.get("splits") or {}) if s in present]
    return order + sorted(present - set(order))


def _clean(x: Any) -> Any:
    """JSON-ready: NaN and inf become None."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def _plan_summary(info: rd.DatasetInfo, groups, splits, view) -> dict[str, Any]:
    """What the spec asked for and what the dataset holds, per split."""
    spec = info.spec
    per_split = []
    counts = info.summary.get("splits") or {}
    corpora: dict[str, dict[str, Any]] = {}
    if view is not None:
        for job in view.jobs_of("corpus"):
            if view.store.exists("corpus", job.key):
                data = view.store.read_data("corpus", job.key)
                corpora[data.get("role", job.params.get("role"))] = data.get("splits", {})
    for split in splits:
        of = [g for g in groups if g["split"] == split]
        speakers = {s.get("speaker") for g in of for s in g["sources"]
                    if s["role"] == "speech" and s.get("speaker")}
        asked = (spec.get("splits") or {}).get(split) or {}
        per_split.append({
            "name": split,
            "groups_asked": asked.get("groups"),
            "groups": len(of),
            "hours": counts.get(split, {}).get("audio_hours",
                                               sum((g["num_samples"] or 0) / (g["sample_rate_hz"]
                                                   or 1) for g in of) / 3600.0),
            "scenes": sorted({g["scene_id"] for g in of}),
            "speakers": len(speakers),
            "corpora": {role: c.get(split) for role, c in sorted(corpora.items())},
        })
    mixture = spec.get("mixture") or {}
    return {"splits": per_split, "roles": sorted(corpora),
            "facts": {k: v for k, v in (
                ("sample rate (Hz)", spec.get("sample_rate_hz")),
                ("microphone", (spec.get("microphone") or {}).get("kind")),
                ("trajectory", (spec.get("trajectory") or {}).get("kind")),
                ("clip length (s)", mixture.get("duration_s")),
                ("speakers per group", mixture.get("speakers")),
                ("seed", spec.get("seed"))) if v is not None}}


def _realism(spec: dict[str, Any], groups: list[dict[str, Any]], splits: Sequence[str]
             ) -> dict[str, Any]:
    """The sections on the realism of issue 30, each None when the dataset does not use it:
    ``facing`` (a histogram per split of where directional talkers face relative to the
    microphone, with shares towards / sideways / away), ``patterns`` (each role's source
    directivity other than omni, drawn per octave band) and ``devices`` (the device presets
    the groups record, with their layout)."""
    from sonicspec.acoustics.directivity import pattern_by_name
    from sonicspec.units import bands_below_nyquist

    per = {s: np.asarray([a for g in groups if g["split"] == s for src in g["sources"]
                          if src["role"] == "speech" for a in src.get("facing_to_mic_deg") or []],
                         dtype=np.float64) for s in splits}
    facing = None
    if any(v.size for v in per.values()):
        facing = {"plot": plots.histogram(
                      per, "talker's facing relative to the direction to the microphone "
                      "(0: facing it)", "deg"),
                  "shares": {s: rd.facing_shares(v) for s, v in per.items()},
                  "n": {s: int(v.size) for s, v in per.items()}}
    bands = bands_below_nyquist(float(spec.get("sample_rate_hz") or 16000))
    patterns = []
    for role, d in sorted((spec.get("directivity") or {}).items()):
        if not isinstance(d, dict) or d.get("pattern", "omni") == "omni":
            continue
        turn = d.get("head_turn")
        entry = {"role": role, "pattern": d["pattern"], "facing": d.get("facing", "walk"),
                 "head_turn": (f"{turn['std_deg']:g}° RMS, {turn['time_constant_s']:g} s"
                               if isinstance(turn, dict) else None),
                 "plot": None, "sofa_path": None}
        if d["pattern"] != "sofa":
            entry["plot"] = plots.directivity_polar(d["pattern"], pattern_by_name(d["pattern"]),
                                                    bands)
        else:
            entry["sofa_path"] = d.get("sofa_path")
        patterns.append(entry)
    counts: dict[str, int] = {}
    for g in groups:
        if g.get("device"):
            counts[g["device"]] = counts.get(g["device"], 0) + 1
    devices = [{"name": name, "groups": n, "plot": plots.device_layout(name)}
               for name, n in sorted(counts.items())]
    return {"facing": facing, "patterns": patterns or None, "devices": devices or None}


def _distributions(spec, groups, splits) -> list[dict[str, Any]]:
    out = []
    for q in rd.quantities(spec):
        per_split = {s: rd.values_of(q, [g for g in groups if g["split"] == s]) for s in splits}
        if not any(v.size for v in per_split.values()):
            continue
        missing = {s: rd.missing_of(q, [g for g in groups if g["split"] == s])
                   for s in splits}
        out.append({"key": q.key, "label": q.label, "unit": q.unit,
                    "stats": {s: rd.stats(v) for s, v in per_split.items()},
                    "missing": missing, "missing_total": sum(missing.values()),
                    "per": "group" if q.per == "group" else "source",
                    "marks": [{"label": m, "value": v} for m, v in q.marks],
                    "ranges": [{"label": m, "lo": lo, "hi": hi} for m, lo, hi in q.ranges],
                    "plot": plots.histogram(per_split, q.label, q.unit, marks=q.marks,
                                            ranges=q.ranges)})
    return out


def _mesh_of(scene: dict[str, Any]):
    from sonicspec.artifacts import read_mesh

    return read_mesh(scene["arrays"], scene["report"])


def _walls(mesh, z_floor: float) -> list[np.ndarray]:
    from sonicspec.export.plots import slice_segments

    walls, _ = slice_segments(mesh, z_floor + WALL_CUT_M)
    low, ids = slice_segments(mesh, z_floor + OBJECT_CUT_M)
    objects = low[mesh.face_object[ids] >= 0] if mesh.face_object is not None else low[:0]
    return [walls, objects]


def _mic_paths(groups: Sequence[dict[str, Any]]) -> list[np.ndarray]:
    """The walks of the groups' moving microphones (none for a static one)."""
    return [np.asarray(g["mic_path_m"], dtype=np.float64) for g in groups
            if g.get("mic_path_m")]


def _paths(g: dict[str, Any]) -> list[np.ndarray]:
    return [np.asarray(s["trajectory_m"], dtype=np.float64) for s in g["sources"]
            if s["role"] == "speech" and s.get("trajectory_m")]


def _statics(g: dict[str, Any]) -> list[list[float]]:
    return [s["position_m"] for s in g["sources"] if s.get("position_m")]


def _scenes(groups, view, warnings: rd.Warnings) -> tuple[list[dict[str, Any]], dict]:
    """Per scene: floor plans with every trajectory, material areas, repair facts; and the
    scene geometry the group pages reuse."""
    out, geometry = [], {}
    for scene_id in sorted({g["scene_id"] for g in groups}):
        of = [g for g in groups if g["scene_id"] == scene_id]
        scene = view.scene(scene_id) if view is not None else None
        entry: dict[str, Any] = {"id": scene_id, "groups": len(of), "plans": [],
                                 "store": scene is not None}
        mesh = None
        if scene is not None:
            mesh = _mesh_of(scene)
            report = scene["report"]
            entry["materials"] = rd.material_areas(scene["arrays"], report["materials"])
            entry["faces"] = report.get("faces")
            entry["kind"] = report.get("kind")
            entry["repair"] = report.get("repair")
            entry["leak"] = report.get("leak")
            entry["warnings"] = rd.scene_warnings(scene_id, report, scene["log_warnings"],
                                                  scene["max_leak_fraction"], warnings)
        floors = sorted({g["floor"] if g["floor"] is not None else 0 for g in of})
        for floor in floors:
            on = [g for g in of if (g["floor"] or 0) == floor]
            walls: list[np.ndarray] = []
            bounds = None
            if mesh is not None:
                zs = scene["floors_z_m"]
                z = zs[floor] if floor < len(zs) else float(mesh.vertices[:, 2].min())
                walls = _walls(mesh, z)
                bounds = (mesh.vertices[:, :2].min(axis=0), mesh.vertices[:, :2].max(axis=0))
                geometry[(scene_id, floor)] = (walls, bounds)
            paths = [p for g in on for p in _paths(g)]
            mics = np.asarray([g["mic_m"] for g in on if g["mic_m"]], dtype=np.float64)
            statics = np.asarray([p for g in on for p in _statics(g)], dtype=np.float64)
            title = f"{scene_id}, floor {floor}: {len(on)} groups, {len(paths)} paths"
            entry["plans"].append(plots.floor_plan(walls, paths, mics.reshape(-1, 3),
                                                   statics.reshape(-1, 3), title=title,
                                                   bounds=bounds, mic_paths=_mic_paths(on)))
        out.append(entry)
    return out, geometry


def _rirs_of(info: rd.DatasetInfo, view, g: dict[str, Any]):
    """Each source's first RIR of group ``g``, its rate and bands: from the dataset's own
    ``rirs/`` folder, else from the store; None when neither has them."""
    names = [s["name"] for s in g["sources"]]
    files = rd.rir_files(info.root, g["group"], names)
    if files:
        import soundfile as sf

        rirs, rate = {}, None
        for name, path in files.items():
            x, rate = sf.read(str(path), dtype="float32", always_2d=True)
            rirs[name] = x[:, 0]
        bands = (info.spec.get("acoustics") or {}).get("bands_hz")
        return rirs, {"sample_rate_hz": rate,
                      "bands_hz": bands if isinstance(bands, list) else None}
    if view is not None and g.get("rir_key"):
        return view.first_rirs(g["rir_key"], g["group"])
    return None


def _band_figures(rir: np.ndarray, rate: float, bands) -> dict[str, Any] | None:
    from sonicspec.acoustics.metrics import room_acoustic_figures
    from sonicspec.errors import AcousticsError

    try:
        return room_acoustic_figures(np.asarray(rir, dtype=np.float64), rate, bands).to_dict()
    except AcousticsError:
        return None


def _group_row(g: dict[str, Any], page: str | None, metadata: str) -> dict[str, Any]:
    speech = [s for s in g["sources"] if s["role"] == "speech"]

    def med(field: str, of) -> float | None:
        v = [s[field] for s in of if s.get(field) is not None]
        return float(np.median(v)) if v else None

    visible = [s["direct_path"] for s in g["sources"] if s["direct_path"]]
    return _clean({
        "group": g["group"], "split": g["split"], "scene": g["scene_id"],
        "speakers": len(speech),
        "gain_db": g["group_gain_db"], "overlap": g["overlap_ratio"],
        "min_distance_m": min((s["distance_min_m"] for s in g["sources"]
                               if s["distance_min_m"] is not None), default=None),
        "path_m": med("path_length_m", speech), "t30_s": med("t30_s", g["sources"]),
        "drr_db": med("drr_db", g["sources"]),
        "visible": (sum(v == "visible" for v in visible) / len(visible)) if visible else None,
        "page": page, "metadata": metadata,
    })


def write_report(dataset: str | Path, output: str | Path | None = None, *,
                 split: str | None = None, group_pages: int | None = None) -> ReportResult:
    """Write the report of the dataset folder ``dataset`` to ``output`` (default
    ``<dataset>/report.html``) and its group pages beside it; see the module docstring."""
    start = time.perf_counter()
    env = _environment()
    plots._figure(1, 1)  # matplotlib's install hint before any work
    root = Path(dataset).resolve()
    info = rd.read_dataset(root)
    path = Path(output).resolve() if output else root / REPORT_NAME
    if path.suffix.lower() not in (".html", ".htm"):
        raise rd.ReportError(f"-o: expected a file name ending in .html, got {path.name!r}")
    known = sorted({g["split"] for g in info.groups})
    if split is not None and split not in known:
        raise rd.ReportError(f"--split: expected one of {', '.join(known)}, got {split!r}")
    spec = info.spec
    if group_pages is None:
        group_pages = ((spec.get("outputs") or {}).get("report") or {}).get(
            "group_pages", DEFAULT_GROUP_PAGES)
    if group_pages < 0:
        raise rd.ReportError(f"--group-pages: expected >= 0, got {group_pages}")
    groups = rd.read_group_facts(info, split)
    if not groups:
        raise rd.ReportError(f"{root}: no group metadata found"
                             + (f" in split {split!r}" if split else ""))
    splits = _split_order(info, groups)
    view = rd.open_store(info)
    warnings = rd.Warnings()
    warnings.missing = [m for m in rd.missing_files(info)
                        if split is None or m["path"].startswith(f"{split}/")]
    rd.group_warnings(groups, warnings)

    distributions = _distributions(spec, groups, splits)
    shares = {s: rd.direct_path_shares([g for g in groups if g["split"] == s]) for s in splits}
    direct = {"table": shares,
              "kinds": sorted({k for v in shares.values() for k in v}),
              "plot": plots.shares({s: {k: v["share"] for k, v in d.items()}
                                    for s, d in shares.items()},
                                   "share of sources by direct path")}
    scenes, geometry = _scenes(groups, view, warnings)
    augmented = {s: rd.augmentation_shares([g for g in groups if g["split"] == s])
                 for s in splits}
    augmentation = ({"table": augmented,
                     "kinds": sorted({k for v in augmented.values() for k in v})}
                    if any(augmented.values()) else None)

    realism = _realism(spec, groups, splits)

    files_dir = files_dir_of(path)
    pages_dir = files_dir / "groups"
    sampled = set(rd.sample_groups(groups, group_pages, int(spec.get("seed", 0))))
    band_values: dict[str, dict[str, list]] = {s: {"t30_s": [], "edt_s": [], "c50_db": []}
                                               for s in splits}
    bands_hz: list[float] | None = None
    rows, pages_written = [], []
    for g in groups:
        page = None
        if g["group"] in sampled:
            name = g["group"].replace("/", "-") + ".html"
            page_html, bands = _group_page(env, info, view, g, pages_dir, path, geometry,
                                           band_values[g["split"]])
            bands_hz = bands_hz or bands
            write_text(pages_dir / name, page_html)
            pages_written.append(pages_dir / name)
            page = rd.relative(pages_dir / name, path.parent)
        rows.append(_group_row(g, page, rd.relative(g["metadata_path"], path.parent)))
    band_plots = []
    if bands_hz:
        for field, label, unit in (("t30_s", "T30", "s"), ("edt_s", "EDT", "s"),
                                   ("c50_db", "C50", "dB")):
            per = {s: np.asarray([[np.nan if x is None else x for x in row]
                                  for row in band_values[s][field]], dtype=np.float64)
                   .reshape(-1, len(bands_hz)) for s in splits}
            band_plots.append({
                "label": label, "unit": unit,
                "medians": {s: [None if not v.size or np.all(np.isnan(v[:, b]))
                                else float(np.nanmedian(v[:, b])) for b in range(len(bands_hz))]
                            for s, v in per.items()},
                "n": {s: len(v) for s, v in per.items()},
                "plot": plots.per_band(per, bands_hz, label, unit)})
    remove_stale_pages(pages_dir, pages_written)

    build = view.build_facts(info.marker.get("dataset_key")) if view is not None else {}
    if (root / "dataset.json").is_file():
        build["dataset_written_utc"] = rd.utc_text((root / "dataset.json").stat().st_mtime)
    spec_text = _spec_yaml(spec) if spec else None
    context = {
        "title": info.summary.get("name") or root.name,
        "description": info.summary.get("description"),
        "dataset": str(root), "split": split,
        "sonicspec_version": info.summary.get("sonicspec_version"),
        "report_version": __version__,
        "dataset_key": info.marker.get("dataset_key"),
        "spec_text": spec_text,
        "store": str(view.root) if view is not None else None,
        "plan": _plan_summary(info, groups, splits, view),
        "build": build,
        "splits": splits,
        "distributions": distributions,
        "direct": direct,
        "augmentation": augmentation,
        "realism": realism,
        "bands_hz": bands_hz, "band_plots": band_plots,
        "scenes": scenes,
        "rows": rows, "groups": len(groups), "group_pages": len(pages_written),
        "group_pages_cap": group_pages,
        "warnings": warnings,
        "thresholds": {"guard_db": rd.GUARD_CUT_DB, "close_m": rd.CLOSE_SOURCE_M},
        "skipped": {role: v.get("count", 0) for role, v in
                    (info.summary.get("corpus_files_skipped") or {}).items()},
    }
    # The page states its own time and size: render once to measure, then with the figures.
    html = env.get_template("report.html.j2").render(**context, cost=None)
    seconds = time.perf_counter() - start
    total = sum(p.stat().st_size for p in pages_written)
    cost = {"seconds": seconds, "page_bytes": len(html.encode()), "pages_bytes": total}
    html = env.get_template("report.html.j2").render(**context, cost=cost)
    write_text(path, html)
    page_bytes = path.stat().st_size
    return ReportResult(path=path, files_dir=files_dir, groups=len(groups),
                        group_pages=len(pages_written), seconds=time.perf_counter() - start,
                        page_bytes=page_bytes, total_bytes=page_bytes + total,
                        missing=warnings.missing)


def remove_stale_pages(pages_dir: Path, keep: Sequence[Path]) -> None:
    """Group pages an earlier report wrote that this one did not (another sample)."""
    if not pages_dir.is_dir():
        return
    keep_names = {p.name for p in keep}
    for p in pages_dir.glob("*.html"):
        if p.name not in keep_names:
            p.unlink()


def _spec_yaml(spec: dict[str, Any]) -> str:
    import yaml

    return yaml.safe_dump(spec, sort_keys=False, allow_unicode=True, width=100)


def _group_page(env, info: rd.DatasetInfo, view, g: dict[str, Any], pages_dir: Path,
                report_path: Path, geometry: dict, band_values: dict[str, list]):
    """One group's page (HTML) and the bands of its RIR figures (None without RIRs)."""
    walls, bounds = geometry.get((g["scene_id"], g["floor"] or 0), ([], None))
    paths = _paths(g)
    labels = [s["name"] for s in g["sources"] if s["role"] == "speech" and s.get("trajectory_m")]
    mic = np.asarray([g["mic_m"]] if g["mic_m"] else [], dtype=np.float64).reshape(-1, 3)
    statics = np.asarray(_statics(g), dtype=np.float64).reshape(-1, 3)
    plan = plots.floor_plan(walls, paths, mic, statics, title=f"{g['group']} in {g['scene_id']}",
                            bounds=bounds, labels=labels, mic_paths=_mic_paths([g]))
    found = _rirs_of(info, view, g)
    rir_plot, bands, figures = None, None, {}
    if found is not None:
        rirs, meta = found
        rate = meta["sample_rate_hz"]
        for name, rir in rirs.items():
            fig = _band_figures(rir, rate, meta["bands_hz"])
            if fig is None:
                continue
            bands = fig["bands_hz"]
            figures[name] = fig
            if name.startswith("source"):  # per-band distributions: the speakers
                for field in ("t30_s", "edt_s", "c50_db"):
                    band_values[field].append(fig[field])
        if rirs:
            rir_plot = plots.rirs_and_edcs(rirs, rate)

    def link(rel: str | None) -> str | None:
        if not rel:
            return None
        target = info.root / rel
        return rd.relative(target, pages_dir) if target.is_file() else None

    meta_path = g["metadata_path"]
    audio = [{"name": s["name"], "src": link(s["file"])} for s in g["sources"]]
    audio += [{"name": f"mixture {name}", "src": link(file)} for name, file in g["mixtures"]]
    html = env.get_template("group.html.j2").render(
        g=g, plan=plan, rir_plot=rir_plot, figures=figures, audio=audio,
        back=rd.relative(report_path, pages_dir), metadata=rd.relative(meta_path, pages_dir),
        sources=[_clean({k: v for k, v in s.items()
                         if k not in ("intervals", "trajectory_m", "position_m", "file")})
                 for s in g["sources"]])
    return html, bands
