"""Issue 28 items 6, 7, 8: what ``sonicspec report`` must not leave unsaid.

6. Missing audio or metadata (or an empty ``metadata.json``): listed in the report, exit 1.
7. A moving microphone: distances from its track (not from ``mic_m``, where it starts), its
   walk on the floor plan, the 0.5 m warning on those distances.
8. RIRs cut while still decaying (``rir_tail``): a warning; a T30 histogram says how many
   values it lacks.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from sonicspec.cli import main
from sonicspec.export import report_data as rd
from sonicspec.testing.datasets import write_synthetic_dataset

GROUPS = {"train": 3, "val": 2}


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    return write_synthetic_dataset(tmp_path_factory.mktemp("trust") / "ds", GROUPS, scenes=1,
                                   duration_s=4.0)


@pytest.fixture
def ds(base: Path, tmp_path: Path) -> Path:
    out = tmp_path / "ds"
    shutil.copytree(base, out)
    return out


def _edit(ds: Path, group: str, fn) -> None:
    path = ds / group / "metadata.json"
    meta = json.loads(path.read_text())
    fn(meta)
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))


def _warnings(page: Path) -> dict[str, str]:
    html = page.read_text(encoding="utf-8")
    return {m.group(1): m.group(2) for m in
            re.finditer(r'<li data-warning="(\w+)">(.*?)</li>', html, re.S)}


def test_a_complete_dataset_reports_with_exit_0(ds: Path, tmp_path: Path) -> None:
    assert main(["report", str(ds), "-o", str(tmp_path / "r.html")]) == 0


def test_a_missing_or_empty_metadata_is_listed_and_exits_1(ds: Path, tmp_path: Path,
                                                            capsys) -> None:
    (ds / "train" / "000001" / "metadata.json").unlink()
    (ds / "val" / "000000" / "metadata.json").write_text("{}\n")
    page = tmp_path / "r.html"
    assert main(["report", str(ds), "-o", str(page)]) == 1
    err = capsys.readouterr().err
    assert "the report is incomplete: 2 file(s)" in err
    assert "train/000001/metadata.json (missing)" in err
    assert "val/000000/metadata.json (empty)" in err
    listed = _warnings(page)["missing"]
    assert "train/000001/metadata.json (missing)" in listed
    assert "val/000000/metadata.json (empty)" in listed
    # the empty group is not counted as a group with figures
    groups = rd.read_group_facts(rd.read_dataset(ds))
    assert sorted(g["group"] for g in groups) == ["train/000000", "train/000002", "val/000001"]


def test_missing_audio_of_a_built_dataset_is_listed_and_exits_1(ds: Path, tmp_path: Path,
                                                                capsys) -> None:
    """A sonicspec build lists its files in checksums.sha256: one gone is named."""
    flac = ds / "train" / "000000" / "source1.flac"
    flac.write_bytes(b"fLaC")
    (ds / "checksums.sha256").write_text(
        f"{'0' * 64}  train/000000/metadata.json\n{'1' * 64}  train/000000/source1.flac\n"
        f"{'2' * 64}  train/000000/source2.flac\n")
    assert main(["report", str(ds), "-o", str(tmp_path / "r.html")]) == 1
    err = capsys.readouterr().err
    assert "1 file(s)" in err and "train/000000/source2.flac (missing)" in err
    assert "source1.flac" not in err


def _moving_mic(meta: dict, end_gap_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The microphone walks from ``mic_m`` to ``end_gap_m`` beside source1's last position,
    over the clip; the tracks say so, as stages.export writes them (the source's distance
    frame by frame from the moving microphone, a heading per frame)."""
    track = meta["source1"]["track"]
    src = np.asarray(track["positions_m"])
    start = np.asarray(meta["mic_m"])
    end = src[-1] + np.array([end_gap_m, 0.0, 0.0])
    t = np.linspace(0.0, 1.0, len(src))[:, None]
    mic = start + t * (end - start)
    meta["microphone_track"] = {"hop_s": 0.01, "positions_m": np.round(mic, 4).tolist(),
                                "yaw_deg": [0.0] * len(src)}
    for name in ("source1", "source2", "source3"):
        tr = meta[name]["track"]
        pos = np.asarray(tr["positions_m"])
        tr["distance_m"] = np.round(np.linalg.norm(pos - mic, axis=1), 4).tolist()
    return src, mic


def test_a_moving_microphone_is_measured_along_its_track(ds: Path, tmp_path: Path,
                                                          monkeypatch) -> None:
    walked: dict[str, np.ndarray] = {}

    def edit(meta):
        walked["src"], walked["mic"] = _moving_mic(meta, 0.3)

    _edit(ds, "train/000000", edit)
    (g,) = [g for g in rd.read_group_facts(rd.read_dataset(ds)) if g["group"] == "train/000000"]
    s1 = g["sources"][0]
    src, mic = walked["src"], walked["mic"]
    exact = np.linalg.norm(src - mic, axis=1)
    assert s1["distance_start_m"] == pytest.approx(exact[0], abs=1e-3)
    assert s1["distance_end_m"] == pytest.approx(0.3, abs=1e-3)
    assert s1["distance_min_m"] == pytest.approx(exact.min(), abs=1e-3)
    # what the report said before: the static mic_m against the source's path
    static = rd.segment_distances(np.asarray(s1["trajectory_m"]), mic[0]).min()
    assert static > 0.5 > s1["distance_min_m"]
    # the floor plans draw the walk (every 10th frame and the last)
    assert np.allclose(g["mic_path_m"][-1], mic[-1], atol=1e-4)
    drawn = []
    from sonicspec.export import report_plots

    real = report_plots.floor_plan

    def spy(*args, mic_paths=(), **kwargs):
        drawn.append([np.asarray(p) for p in mic_paths])
        return real(*args, mic_paths=mic_paths, **kwargs)

    monkeypatch.setattr(report_plots, "floor_plan", spy)
    page = tmp_path / "r.html"
    assert main(["report", str(ds), "-o", str(page), "--group-pages", "5"]) == 0
    assert any(len(d) == 1 and np.allclose(d[0][-1], mic[-1], atol=1e-4) for d in drawn)
    close = _warnings(page)["close"]
    assert f"train/000000 source1 ({exact.min():.2f} m)" in close, close


def test_a_moving_microphone_without_source_tracks_uses_the_path(ds: Path) -> None:
    """No frame-by-frame track: the source's path against every place the microphone passes
    (the minimum a lower bound), the ends against the walk's ends."""
    def edit(meta):
        _moving_mic(meta, 0.3)
        for name in ("source1", "source2", "source3"):
            del meta[name]["track"]

    _edit(ds, "train/000000", edit)
    (g,) = [g for g in rd.read_group_facts(rd.read_dataset(ds)) if g["group"] == "train/000000"]
    s1 = g["sources"][0]
    path = np.asarray(s1["trajectory_m"])
    mic = np.asarray(g["mic_path_m"])
    assert s1["distance_end_m"] == pytest.approx(np.linalg.norm(path[-1] - mic[-1]), abs=1e-3)
    assert s1["distance_min_m"] <= 0.3 + 1e-3


def test_truncated_rirs_and_missing_t30_are_said(ds: Path, tmp_path: Path) -> None:
    tail = {"rule": "fixed", "limit_s": 1.0, "limit_field": "max_rir_length_s",
            "decay_end_s": 1.0, "decay_60db_s": [None, None, 0.9, 0.7, 0.5, 0.3],
            "continued_from_s": [None] * 6,
            "level_at_limit_db": [-46.0, -49.5, None, None, None, None],
            "fitted_t60_s": [4.6, 4.1, None, None, None, None]}

    def edit(meta):
        meta["source2"]["rir_tail"] = tail
        meta["source2"]["t30_s"] = None
        meta["noise"]["t30_s"] = None

    _edit(ds, "val/000001", edit)
    page = tmp_path / "r.html"
    assert main(["report", str(ds), "-o", str(page)]) == 0
    cut = _warnings(page)["truncated"]
    assert "1 source(s) whose RIRs were cut while still decaying" in cut
    assert "val/000001 source2 (cut at 1 s; 125 Hz at -46 dB, 250 Hz at -50 dB" in cut
    assert "fitted T60 up to 4.6 s" in cut
    html = page.read_text(encoding="utf-8")
    card = html[html.index('data-quantity="t30"'):]
    card = card[:card.index('<div class="card"')]
    assert 'data-missing="2"' in card and "val 2" in card


def test_sources_whose_image_source_search_stopped_early_are_said(ds: Path,
                                                                  tmp_path: Path) -> None:
    """Issue 27 item 6: a scan's noise can stop the image-source search below the order
    asked; the report says which sources, in which scene, and why (metadata.json's
    ``image_source_order``)."""
    page = tmp_path / "r.html"
    assert main(["report", str(ds), "-o", str(page)]) == 0
    assert "order" not in _warnings(page)

    def edit(meta):
        meta["source1"]["image_source_order"] = {
            "asked": 3, "reached": 1, "stopped": "order 2 needs more than 2,000,000 candidates"}
        meta["source2"]["image_source_order"] = {"asked": 3, "reached": 3, "stopped": None}

    _edit(ds, "train/000000", edit)
    assert main(["report", str(ds), "-o", str(page)]) == 0
    said = _warnings(page)["order"]
    assert "1 source(s) whose exact early reflections stopped below" in said
    assert re.search(r"train/000000 source1 in \S+ \(order 1 of 3: order 2 needs more than "
                     r"2,000,000 candidates\)", said), said
