"""``sonicspec report``: the figures in the page against oracles computed here from the
metadata, the warnings, a SonicSet-style folder, the errors, and (test_report_browser.py)
the demo's report in headless Chromium."""

from __future__ import annotations

import itertools
import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from sonicspec.cli import main
from sonicspec.export import report_data as rd
from sonicspec.export.report import write_report
from sonicspec.testing.datasets import synthetic_metadata, write_synthetic_dataset

GROUPS = {"train": 12, "val": 4, "test": 4}


class PageFigures(HTMLParser):
    """The per-split rows of every distribution card: {(quantity, split): attributes}."""

    def __init__(self) -> None:
        super().__init__()
        self.quantity: str | None = None
        self.rows: dict[tuple[str, str], dict[str, str]] = {}
        self.direct: dict[tuple[str, str], int] = {}
        self.split: str | None = None
        self.warnings: list[str] = []
        self.plan_groups: dict[str, int] = {}
        self._plan_split: str | None = None
        self._in_groups_cell = False

    def handle_starttag(self, tag, attrs) -> None:
        a = dict(attrs)
        if "data-quantity" in a:
            self.quantity = a["data-quantity"]
        if tag == "tr" and "data-split" in a:
            self.split = a["data-split"]
            if "data-n" in a and self.quantity:
                self.rows[(self.quantity, a["data-split"])] = a
            self._plan_split = a["data-split"]
        if tag == "td" and "data-kind" in a and self.split:
            self.direct[(self.split, a["data-kind"])] = int(a["data-count"])
        if "data-warning" in a:
            self.warnings.append(a["data-warning"])
        self._in_groups_cell = tag == "td" and a.get("class") == "groups"

    def handle_data(self, data) -> None:
        if self._in_groups_cell and self._plan_split:
            self.plan_groups[self._plan_split] = int(data)
            self._in_groups_cell = False


def page_figures(path: Path) -> PageFigures:
    parser = PageFigures()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    root = write_synthetic_dataset(tmp_path_factory.mktemp("synthetic") / "ds", GROUPS,
                                   scenes=2, duration_s=10.0)
    # One group the guard cut by 4 dB and one source 0.3 m from the microphone.
    path = root / "val" / "000001" / "metadata.json"
    meta = json.loads(path.read_text())
    meta["group_gain_db"] = -4.0
    mic = np.asarray(meta["mic_m"])
    meta["source2"]["trajectory_m"][1] = (mic + np.array([0.3, 0.0, 0.0])).tolist()
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))
    return root


def _metadata(root: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(root.glob("*/*/metadata.json"))]


def _mask(n: int, intervals) -> np.ndarray:
    m = np.zeros(n, bool)
    for a, b in intervals:
        m[a:b] = True
    return m


def _oracle(metas: list[dict], split: str) -> dict[str, np.ndarray]:
    """The figures, computed here the slow and obvious way: sample masks, dense sampling."""
    out: dict[str, list[float]] = {"t30": [], "group_gain": [], "path_length": [],
                                   "overlap": [], "speech_activity": [], "distance_min": [],
                                   "speech_after": []}
    for m in metas:
        if m["split"] != split:
            continue
        n = m["num_samples"]
        names = [k for k in m if k.startswith("source")] + ["noise", "music"]
        out["t30"] += [m[k]["t30_s"] for k in names]
        out["group_gain"].append(m["group_gain_db"])
        speakers = [_mask(n, m[k]["start_end_points"]) for k in names if k.startswith("source")]
        count = np.sum(speakers, axis=0)
        out["overlap"].append((count >= 2).sum() / (count >= 1).sum())
        out["speech_activity"].append((count >= 1).mean())
        mic = np.asarray(m["mic_m"])
        for k in names:
            e = m[k]
            if k.startswith("source"):
                out["path_length"].append(e["path_length_m"])
                out["speech_after"].append(e["loudness"]["output_lufs"])
                p = np.asarray(e["trajectory_m"])
                t = np.linspace(0, 1, 20001)[:, None]
                dense = np.concatenate([a + t * (b - a) for a, b in itertools.pairwise(p)])
            else:
                dense = np.asarray([e["position_m"]])
            out["distance_min"].append(np.linalg.norm(dense - mic, axis=1).min())
    return {k: np.asarray(v) for k, v in out.items()}


def test_figures_in_the_page_equal_the_metadata(synthetic: Path, tmp_path: Path) -> None:
    result = write_report(synthetic, tmp_path / "r.html", group_pages=2)
    assert result.groups == sum(GROUPS.values()) and result.group_pages == 2
    page = page_figures(result.path)
    metas = _metadata(synthetic)
    assert page.plan_groups == GROUPS
    for split in GROUPS:
        oracle = _oracle(metas, split)
        for key, values in oracle.items():
            row = page.rows[(key, split)]
            assert int(row["data-n"]) == values.size, (key, split)
            tol = 2e-4 if key == "distance_min" else 1e-9  # the oracle samples the path
            assert float(row["data-median"]) == pytest.approx(np.median(values), abs=tol), (
                key, split)
        kinds = [m[k]["direct_path"] for m in metas if m["split"] == split
                 for k in m if isinstance(m[k], dict) and "direct_path" in m[k]]
        for kind in set(kinds):
            assert page.direct[(split, kind)] == kinds.count(kind)
    assert sorted(page.warnings) == ["close", "guard"]
    text = result.path.read_text()
    assert "val/000001 (-4.0 dB)" in text
    close = re.search(r"val/000001 source2 \((\d\.\d\d) m\)", text)
    assert close is not None and float(close.group(1)) <= 0.3  # its path passes 0.3 m or closer
    # the table's data: every group once, pages for the 2 sampled ones
    rows = json.loads(text.split('id="group-data">')[1].split("</script>")[0])
    assert sorted(r["group"] for r in rows) == sorted(m["group"] for m in metas)
    assert sum(r["page"] is not None for r in rows) == 2
    for r in rows:
        if r["page"]:
            assert (result.path.parent / r["page"]).is_file()
        assert (result.path.parent / r["metadata"]).is_file()


def test_overlap_and_activity_against_sample_masks() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = 400
        speakers = []
        for _ in range(int(rng.integers(1, 4))):
            starts = np.sort(rng.integers(0, n, int(rng.integers(1, 4))))
            speakers.append([[int(a), int(min(n, a + rng.integers(0, 120)))] for a in starts])
        masks = [_mask(n, s) for s in speakers]
        count = np.sum(masks, axis=0)
        got = rd.overlap_ratio(speakers)
        if (count >= 1).sum() == 0:
            assert got is None
        else:
            assert got == pytest.approx((count >= 2).sum() / (count >= 1).sum())
        flat = [iv for s in speakers for iv in s]
        assert rd._union_length(flat) == (count >= 1).sum()


def test_distance_to_a_path_is_exact() -> None:
    path = np.array([[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [4.0, 3.0, 1.0]])
    assert rd.segment_distances(path, np.array([2.0, 1.5, 1.0])).min() == pytest.approx(1.5)
    assert rd.segment_distances(path, np.array([5.0, 4.0, 1.0])).min() == pytest.approx(
        np.sqrt(2))
    assert rd.segment_distances(path[:1], np.array([3.0, 4.0, 1.0])).min() == pytest.approx(5)


def test_metadata_is_read_without_its_tracks(tmp_path: Path) -> None:
    meta = synthetic_metadata("train/000000", "room", 1, duration_s=2.0)
    meta["microphone_track"] = {"hop_s": 0.01, "positions_m": [[1, 2, 3]] * 5}
    path = tmp_path / "metadata.json"
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))
    got = rd.read_metadata(path)
    assert got["source1"]["track"] == {} and got["microphone_track"] == {}
    for name in ("source1", "noise"):
        assert {k: v for k, v in got[name].items() if k != "track"} == {
            k: v for k, v in meta[name].items() if k != "track"}
    # A "track" with a nested object is not cut: the file is parsed whole.
    meta["source1"]["track"] = {"nested": {"a": 1}, "distance_m": [1.0]}
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))
    assert rd.read_metadata(path)["source1"]["track"] == meta["source1"]["track"]
    path.write_text("{not json")
    with pytest.raises(rd.ReportError, match=r"metadata\.json: unreadable JSON"):
        rd.read_metadata(path)


def test_sampled_pages_cover_every_split_and_scene_and_repeat() -> None:
    groups = [{"group": f"{s}/{i:06d}", "split": s, "scene_id": f"{s}-{i % 3}"}
              for s, n in (("train", 50), ("val", 5), ("test", 1)) for i in range(n)]
    first = rd.sample_groups(groups, 7, seed=4)
    assert first == rd.sample_groups(groups, 7, seed=4) and len(first) == 7
    by = {g["group"]: (g["split"], g["scene_id"]) for g in groups}
    assert {by[g] for g in first} == {(g["split"], g["scene_id"]) for g in groups}
    assert rd.sample_groups(groups, 7, seed=5) != first
    assert len(rd.sample_groups(groups, 1000, seed=4)) == len(groups)
    assert rd.sample_groups(groups, 0, seed=4) == []


def test_a_sonicset_style_folder_reports_what_it_has(synthetic: Path, tmp_path: Path) -> None:
    """No dataset.json, no marker, no store; scene ids as the sonicset preset names them
    (mp3d/<building>), and one group in the SonicSet release's plain form."""
    root = tmp_path / "sonicset"
    for path in sorted(synthetic.glob("*/*/metadata.json")):
        meta = json.loads(path.read_text())
        meta["scene_id"] = f"mp3d/{meta['scene_id']}"
        target = root / path.relative_to(synthetic)
        target.parent.mkdir(parents=True)
        target.write_text(json.dumps(meta))
    plain = root / "test" / "000003" / "metadata.json"
    meta = json.loads(plain.read_text())
    plain.write_text(json.dumps({k: {f: meta[k][f] for f in ("audio", "start_end_points")}
                                 for k in ("source1", "source2", "source3", "noise", "music")}))
    out = tmp_path / "sonicset.html"
    assert main(["report", str(root), "-o", str(out), "--group-pages", "3"]) == 0
    page = page_figures(out)
    assert page.rows[("t30", "test")]["data-n"] == str(3 * 5)  # the plain group has none
    assert page.rows[("t30", "train")]["data-n"] == str(12 * 5)
    text = out.read_text()
    assert "mp3d/scene00" in text and "artifact store this dataset names was not found" in text
    assert "No dataset.json" in text


def test_one_split(synthetic: Path, tmp_path: Path) -> None:
    result = write_report(synthetic, tmp_path / "val.html", split="val", group_pages=2)
    assert result.groups == GROUPS["val"]
    page = page_figures(result.path)
    assert {split for _, split in page.rows} == {"val"}


def test_bad_input_is_named_with_exit_code_2(synthetic: Path, tmp_path: Path, capsys) -> None:
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert "nowhere: no such folder" in capsys.readouterr().err
    assert main(["report", str(tmp_path)]) == 2
    assert "expected a dataset folder" in capsys.readouterr().err
    assert main(["report", str(synthetic), "--split", "trian", "-o",
                 str(tmp_path / "x.html")]) == 2
    assert "--split: expected one of test, train, val, got 'trian'" in capsys.readouterr().err
    assert main(["report", str(synthetic), "-o", str(tmp_path / "x.pdf")]) == 2
    assert "-o: expected a file name ending in .html, got 'x.pdf'" in capsys.readouterr().err
    assert main(["report", str(synthetic), "--group-pages", "-1"]) == 2
    assert "--group-pages: expected >= 0, got -1" in capsys.readouterr().err
    broken = tmp_path / "broken"
    shutil.copytree(synthetic, broken)
    (broken / "train" / "000002" / "metadata.json").write_text("{")
    assert main(["report", str(broken), "-o", str(tmp_path / "b.html")]) == 2
    assert "train/000002/metadata.json: unreadable JSON" in capsys.readouterr().err


def test_group_pages_of_an_earlier_sample_are_removed(synthetic: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.html"
    write_report(synthetic, out, group_pages=3, split="test")
    write_report(synthetic, out, group_pages=1, split="test")
    assert len(list((tmp_path / "r_files" / "groups").glob("*.html"))) == 1


def test_scene_warnings_from_the_mesh_report_and_log() -> None:
    """The mesh stage's leak message and the material library's fallback message, as the
    mesh job's log holds them (time stamp and level first)."""
    warnings = rd.Warnings()
    log = ["2026-11-26 02:17:41,063 WARNING scene 'mp3d/abc': expected a material for every "
           "face label, got none for faces without a label (1.3 % of the area -> Default); ..."]
    lines = rd.scene_warnings("mp3d/abc", {"leak": {"fraction": 0.0}}, log, 0.001, warnings)
    assert lines == [log[0][len("2026-11-26 02:17:41,063 WARNING "):]]
    assert warnings.default_materials == [{"scene": "mp3d/abc", "message": lines[0]}]
    assert warnings.leaked_scenes == []
    leak = ("scene 'mp3d/x': 2.00% of 1000 test rays leave the mesh (allowed: 0.10%); raise "
            "repair.max_hole_size_m or fix the scan")
    rd.scene_warnings("mp3d/x", {"leak": {"fraction": 0.02}, "warnings": [leak]}, [leak],
                      0.001, warnings)
    assert warnings.leaked_scenes == [{"scene": "mp3d/x", "fraction": 0.02, "allowed": 0.001}]
    rd.scene_warnings("mp3d/y", {"leak": {"fraction": 0.0005}}, [], 0.001, warnings)
    assert len(warnings.leaked_scenes) == 1 and warnings.count == 2  # within what is allowed


def test_the_report_needs_its_libraries(monkeypatch, synthetic: Path, tmp_path: Path,
                                        capsys) -> None:
    from sonicspec.stages import preflight

    monkeypatch.setattr(preflight, "module_available", lambda name: name != "jinja2")
    assert main(["report", str(synthetic)]) == 2
    assert "sonicspec report needs jinja2: pip install 'sonicspec[report]'" in (
        capsys.readouterr().err)
    spec = tmp_path / "demo.yaml"
    text = (Path(__file__).resolve().parents[1] / "specs" / "demo.yaml").read_text()
    spec.write_text(text.replace("  groups_per_shard: 2\n",
                                 "  groups_per_shard: 2\n  report: {enabled: true}\n"))
    assert main(["build", str(spec)]) == 2
    assert "outputs.report.enabled needs jinja2" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_report_settings_rerun_no_export(tmp_path: Path) -> None:
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec

    text = (Path(__file__).resolve().parents[1] / "specs" / "demo.yaml").read_text()
    plain, asked = tmp_path / "a.yaml", tmp_path / "b.yaml"
    plain.write_text(text)
    asked.write_text(text.replace("  groups_per_shard: 2\n", "  groups_per_shard: 2\n"
                                  "  report: {enabled: true, group_pages: 7}\n"))
    before = {j.key for j in compile_spec(load_spec(plain)).jobs}
    after = compile_spec(load_spec(asked))
    assert {j.step for j in after.jobs if j.key not in before} == {"dataset"}


def test_one_row_of_a_stored_array(tmp_path: Path) -> None:
    from sonicspec.errors import StoreError
    from sonicspec.store import ArtifactStore

    store = ArtifactStore(tmp_path / "store")
    key = "ab" * 32
    stack = np.arange(3 * 2 * 5, dtype=np.float32).reshape(3, 2, 5)
    store.write("rir", key, {"g0_s0": stack}, data={"groups": []})
    assert np.array_equal(store.read_array("rir", key, "g0_s0", 1), stack[1])
    with pytest.raises(StoreError, match="rir cdcdcdcdcdcd: no artifact"):
        store.read_array("rir", "cd" * 32, "g0_s0", 0)
    with pytest.raises(StoreError, match="cannot read array 'nope' row 0"):
        store.read_array("rir", key, "nope", 0)
