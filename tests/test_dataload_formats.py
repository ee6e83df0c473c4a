"""Readers of external layouts (sonicspec.dataload.formats): each tiny fixture in its real
layout (tests/layout_cases.py) reads back as its files, scores the mixture as SI-SNRi 0 and the
references as the ceiling, and an incomplete layout names what is missing."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import layout_cases as lc
import numpy as np
import pytest
import soundfile as sf

from sonicspec.dataload import MixingConfig, SonicspecDataset
from sonicspec.dataload.evaluate import evaluate
from sonicspec.dataload.folder import DatasetError
from sonicspec.dataload.formats import detect, open_dataset

# name, writer, the folder a user points at (relative to tmp), split, task
CASES: list[tuple[str, Callable, str, str, str]] = [
    ("librimix", lc.librimix, "Libri2Mix/wav8k/min", "test", "separation"),
    ("librimix", lc.librimix, "Libri2Mix", "test", "enhancement"),
    ("wham", lc.wham, "wham_mix", "tt", "separation"),
    ("wham", lambda p: lc.wham(p, reverb=True), "whamr/wav8k/min", "test", "separation"),
    ("lrs2mix", lc.lrs2mix, "LRS2-2Mix", "test", "separation"),
    ("voicebank", lc.voicebank, ".", "test", "enhancement"),
    ("dns", lc.dns, "test_set", "test", "enhancement"),
    ("sonicset", lc.sonicset, ".", "test-noise", "separation"),
    ("sonicset", lc.sonicset, ".", "test", "enhancement"),
    ("plain", lc.plain, ".", "test", "separation"),
    ("sonicset", lc.sonicset_raw, "SonicSet/scene_datasets/mp3d", "test", "separation"),
]
IDS = [f"{c[0]}-{c[2].replace('/', '_')}-{c[4]}" for c in CASES]


def _read(path: Path) -> np.ndarray:
    x, _ = sf.read(str(path), dtype="float32", always_2d=True)
    return x.T


@pytest.mark.parametrize(("name", "writer", "where", "split", "task"), CASES, ids=IDS)
def test_items_are_the_files_read_directly(tmp_path: Path, name: str, writer, where: str,
                                           split: str, task: str) -> None:
    files = writer(tmp_path)
    root = tmp_path / where
    assert detect(root) == name
    folder = open_dataset(root)
    seen = 0
    for group in folder.groups(split):
        mine = files[group.id]
        for m in group.mixtures(task):
            if not m.get("file"):  # the raw SonicSet folders: mixed from its tracks
                for c in m["components"]:
                    np.testing.assert_array_equal(group.read(c), _read(mine[c]))
                seen += 1
                continue
            np.testing.assert_array_equal(group.read(m["file"]), _read(mine[m["name"]]))
            for t in m["targets"]:
                np.testing.assert_array_equal(group.read(t), _read(mine[t]))
            assert group.num_samples == _read(mine[m["name"]]).shape[1]
            seen += 1
    assert seen >= 2
    # The loader gives the same items, whole and as written.
    data = SonicspecDataset(root, split, task, config=MixingConfig(
        dynamic=False, crop_s=None, sir_db=None, snr_db=None))
    for i in range(len(data)):
        item = data[i]
        mine = files[item["group"]]
        m = next(m for m in data.items if m[0] == item["group"]
                 and m[1]["name"] == item["mixture_name"])[1]
        want = (_read(mine[item["mixture_name"]]) if m.get("file") else
                sum(_read(mine[c]).astype(np.float64) for c in m["components"]))
        np.testing.assert_allclose(item["mixture"], want, rtol=0, atol=1e-6)
        for k, t in enumerate(m["targets"]):
            np.testing.assert_array_equal(item["targets"][k], _read(mine[t]))


@pytest.mark.parametrize(("name", "writer", "where", "split", "task"), CASES, ids=IDS)
def test_oracle_mixture_scores_zero_and_references_the_ceiling(
        tmp_path: Path, name: str, writer, where: str, split: str, task: str) -> None:
    writer(tmp_path)
    # SDR once (fast_bss_eval is slow to load); SI-SNR on every layout.
    metrics = ["si_snr", "si_snri", *(["sdri"] if name == "librimix" else [])]
    rows = evaluate(tmp_path / where, split, task, oracle=True, metrics=metrics)
    mix = [r for r in rows if r["method"] == "oracle_mixture"]
    top = [r for r in rows if r["method"] == "oracle_targets"]
    assert mix and len(mix) == len(top)
    for r in mix:
        assert r["si_snri"] == pytest.approx(0.0, abs=1e-9)
        assert r.get("sdri", 0.0) == pytest.approx(0.0, abs=1e-9)
    for r in top:
        assert r["si_snr"] >= 100.0


def test_librimix_variants_mixture_filter_and_libri3mix(tmp_path: Path) -> None:
    lc.librimix(tmp_path / "a", n_src=3, rate=16000, mode="max")
    folder = open_dataset(tmp_path / "a" / "Libri3Mix")
    g = folder.groups("test")[0]
    assert g.speakers == ("source1", "source2", "source3") and g.sample_rate_hz == 16000
    assert [m["name"] for m in g.mixtures("separation")] == ["mix_both", "mix_clean"]
    rows = evaluate(tmp_path / "a" / "Libri3Mix", "test", "separation", oracle=True,
                    metrics=["si_snri"], mixtures=["mix_both"])
    assert {r["mixture"] for r in rows} == {"mix_both"} and len(rows) == 2 * 2 * 3
    with pytest.raises(DatasetError, match=r"no separation mixture named mix_x; its "
                       r"separation mixtures are \['mix_both', 'mix_clean'\]"):
        evaluate(tmp_path / "a" / "Libri3Mix", "test", "separation", oracle=True,
                 metrics=["si_snri"], mixtures=["mix_x"])
    # Two variants under one top folder: the reader asks which.
    lc.librimix(tmp_path / "a", n_src=3, rate=8000, mode="min")
    with pytest.raises(DatasetError, match=r"holds 2 LibriMix variants \(wav8k/min, "
                       r"wav16k/max\); point at one of them"):
        open_dataset(tmp_path / "a" / "Libri3Mix", "librimix")


def test_dynamic_mixing_redraws_a_layout_with_its_noise(tmp_path: Path) -> None:
    lc.librimix(tmp_path)
    data = SonicspecDataset(tmp_path / "Libri2Mix", "test", "separation",
                            config=MixingConfig(crop_s=0.5), background="noise")
    item = data[0]
    assert item["mixture"].shape == (1, 4000) and item["targets"].shape == (2, 1, 4000)
    assert -6.0 <= float(item["sir_db"][0]) <= 6.0 and 10.0 <= item["snr_db"] <= 20.0
    # A layout whose noise is not released cannot be re-mixed: said, not silently clean.
    lc.voicebank(tmp_path / "vb")
    with pytest.raises(DatasetError, match="not among its files .* use "
                       r"MixingConfig\(dynamic=False\)"):
        SonicspecDataset(tmp_path / "vb", "test", "enhancement", config="paper")


def test_raw_sonicset_folders_mix_like_the_released_loader(tmp_path: Path) -> None:
    files = lc.sonicset_raw(tmp_path)
    root = tmp_path / "SonicSet/scene_datasets/mp3d"
    g = open_dataset(root).group("test/2t7WUuJeko7/1089-121-1221")
    assert g.speakers == ("source1", "source2", "source3")
    assert g.backgrounds == ("noise", "music")
    assert g.metadata["source2"]["start_end_points"] == [[0, 80000]]
    assert g.metadata["source2"]["words"] == ["HELLO"]
    assert [m["name"] for m in g.mixtures("separation")][:3] == [
        "sep_s1s2_noise", "sep_s1s3_noise", "sep_s2s3_noise"]
    # The released training loader's draws: 4 s crops, ±6 dB SIR, 10-20 dB SNR.
    data = SonicspecDataset(root, "test", "separation", config="sonicsim",
                            background="music")
    item = data[3]
    assert item["mixture"].shape == (1, 64000) and item["targets"].shape == (2, 1, 64000)
    assert 10.0 <= item["snr_db"] <= 20.0
    speech = item["targets"].sum(axis=0)[0].astype(np.float64)
    music = item["mixture"][0] - speech
    assert 10 * np.log10(np.mean(speech ** 2) / np.mean(music ** 2)) == pytest.approx(
        item["snr_db"], abs=0.01)
    assert files  # the fixture's files are the ones read (test_items_are_the_files_...)


def _break(tmp: Path, how: str) -> tuple[Path, str | None, str]:
    """A damaged layout, the format to ask for, and the message expected."""
    if how == "librimix-missing-source":
        lc.librimix(tmp)
        (tmp / "Libri2Mix/wav8k/min/test/s2/1089-134686-0000_121-121726-0000.wav").unlink()
        return (tmp / "Libri2Mix", None,
                r"s2/1089-134686-0000_121-121726-0000.wav: missing; the librimix layout "
                r"lists it as source2 of test/1089")
    if how == "librimix-column":
        lc.librimix(tmp)
        csv = tmp / "Libri2Mix/wav8k/min/metadata/mixture_test_mix_clean.csv"
        csv.write_text(csv.read_text().replace("mixture_path", "mix_path"))
        return tmp / "Libri2Mix", None, r"mixture_test_mix_clean.csv: no column 'mixture_path'"
    if how == "librimix-length":
        lc.librimix(tmp)
        for p in (tmp / "Libri2Mix/wav8k/min/metadata").glob("*.csv"):
            p.write_text(p.read_text().replace(",8000\n", ",8001\n"))
        return (tmp / "Libri2Mix", None, r"mix_(both|clean|single)/1089.*\.wav: 8000 samples, "
                r"but the librimix metadata gives test/1089.* a length of 8001")
    if how == "voicebank-clean":
        lc.voicebank(tmp)
        for p in (tmp / "clean_testset_wav").iterdir():
            p.unlink()
        (tmp / "clean_testset_wav").rmdir()
        return tmp, None, r"clean_testset_wav: missing; the VoiceBank-DEMAND layout pairs"
    if how == "dns-fileid":
        lc.dns(tmp)
        noisy = tmp / "test_set/synthetic/no_reverb/noisy"
        next(noisy.iterdir()).rename(noisy / "some_noisy_clip.wav")
        return tmp / "test_set", None, r"some_noisy_clip.wav: no fileid_<N> in its name"
    if how == "wham-length":
        lc.wham(tmp)
        lc.write(tmp / f"wham_mix/wav8k/min/tt/s1/{lc.WSJ_NAMES[0]}.wav", np.zeros(7999),
                 8000)
        return (tmp / "wham_mix", None, r"s1/011a0101.*\.wav: 7999 samples at 8000 Hz, but "
                r"tt/mix_both/011a0101.*\.wav of tt/011a0101.* has 8000 at 8000 Hz")
    if how == "plain-reference":
        lc.plain(tmp)
        (tmp / "test/room1/take1/s1.wav").unlink()
        return tmp, None, r"take1: references \['s2.wav'\]; expected s1 … s1 with none missing"
    if how == "sonicset-wrong-format":
        lc.plain(tmp)
        return tmp, "sonicset", r"no test-noise/, test-music/, enh-test-noise/ or " \
                                r"enh-test-music/ \(the benchmarks\), nor train\|val\|test/" \
                                r"<scene>/<speakers>/moving_audio_1.wav \(the raw folders\); " \
                                r"expected the released SonicSet layout"
    if how == "lrs2mix-references":
        lc.lrs2mix(tmp)
        for ref in ("s1", "s2"):
            for f in (tmp / "LRS2-2Mix/tt" / ref).iterdir():
                f.unlink()
            (tmp / "LRS2-2Mix/tt" / ref).rmdir()
        return tmp / "LRS2-2Mix", "lrs2mix", r"tt: mix/ but no s1/, s2/"
    if how == "plain-flat":
        lc.write(tmp / "test" / "mixture.wav", np.zeros(100), 16000)
        return tmp, "plain", r"test: a mixture directly in the split folder"
    if how == "sonicset-raw-json":
        lc.sonicset_raw(tmp)
        raw = tmp / "SonicSet/scene_datasets/mp3d"
        next(raw.glob("test/*/*/json_data.json")).unlink()
        return raw, None, r"json_data.json: missing; the sonicset layout has one beside"
    if how == "sonicset-raw-music":
        lc.sonicset_raw(tmp)
        raw = tmp / "SonicSet/scene_datasets/mp3d"
        next(raw.glob("test/*/*/music_audio.wav")).unlink()
        return raw, None, r"no music_audio.wav or music.wav; the released SonicSet layout"
    if how == "unknown":
        (tmp / "empty").mkdir()
        return (tmp / "empty", None, r"empty/dataset.json: missing; expected a dataset "
                r"folder built by `sonicspec build` .* or a test set in one of the layouts "
                r"\['sonicset', .*\(give --format to be told what it lacks\)")
    if how == "format-name":
        return tmp, "timit", r"format: expected one of \['auto', 'sonicspec', 'sonicset'"
    raise AssertionError(how)


@pytest.mark.parametrize("how", ["librimix-missing-source", "librimix-column",
                                 "librimix-length", "voicebank-clean", "dns-fileid",
                                 "wham-length", "plain-reference", "sonicset-wrong-format",
                                 "lrs2mix-references", "plain-flat", "sonicset-raw-json",
                                 "sonicset-raw-music", "unknown", "format-name"])
def test_an_incomplete_layout_names_what_is_missing(tmp_path: Path, how: str) -> None:
    root, fmt, message = _break(tmp_path, how)
    with pytest.raises(DatasetError, match=message):
        evaluate(root, "test", "separation" if "voicebank" not in how and "dns" not in how
                 else "enhancement", oracle=True, metrics=["si_snri"], format=fmt)


# -- cross-set tables ---------------------------------------------------------------------

def _estimates(root: Path, model_dir: Path, split: str, task: str, kind: str,
               mixtures: tuple[str, ...]) -> None:
    """Estimates of every mixture: the references (``ceiling``) or the mixture (``zero``)."""
    for g in open_dataset(root).groups(split):
        for m in g.mixtures(task):
            if m["name"] not in mixtures:
                continue
            x = (np.stack([g.read(t)[0] for t in m["targets"]]) if kind == "ceiling"
                 else np.stack([g.read(m["file"])[0]] * len(m["targets"])))
            path = model_dir / g.id / f"{m['name']}.wav"
            path.parent.mkdir(parents=True, exist_ok=True)
            sf.write(str(path), x.T, g.sample_rate_hz, subtype="FLOAT")


def test_cross_set_table_of_models_by_sets(tmp_path: Path, capsys) -> None:
    from sonicspec.cli import main

    lc.librimix(tmp_path / "data")
    lc.plain(tmp_path / "data" / "real")
    sets = {"libri2mix": tmp_path / "data" / "Libri2Mix", "real": tmp_path / "data" / "real"}
    est = tmp_path / "estimates"
    for s, root in sets.items():
        _estimates(root, est / "ceiling" / s, "test", "separation", "ceiling",
                   ("mix_both", "mixture"))
        _estimates(root, est / "identity" / s, "test", "separation", "zero",
                   ("mix_both", "mixture"))
    _estimates(sets["real"], est / "partial" / "real", "test", "separation", "zero",
               ("mixture",))
    out = tmp_path / "table"
    code = main(["evaluate", "--estimates-root", str(est), "--split", "test", "--task",
                 "separation", "--sets", f"libri2mix={sets['libri2mix']},{sets['real']}",
                 "--mixture", "mix_both", "--mixture", "mixture", "--oracle",
                 "--metrics", "si_snr", "si_snri", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "estimates/partial/libri2mix: no such folder" in captured.err
    md = (out / "table.md").read_text()
    lines = md.splitlines()
    assert lines[0] == ("| Model | libri2mix SI-SNR | libri2mix SI-SNRi | real SI-SNR | "
                        "real SI-SNRi |")
    rows = {ln.split(" | ")[0].lstrip("| "): ln for ln in lines[2:6]}
    assert list(rows) == ["Mixture", "Oracle", "ceiling", "identity"]
    assert rows["Mixture"].endswith("| 0.00 |") and " 0.00 | " in rows["Mixture"]
    assert rows["identity"].split(" | ")[2] == "0.00"
    assert "**" in rows["ceiling"] and lines[6].startswith("| partial | - | - |")
    assert "partial/libri2mix has no estimates" in md
    table = list(__import__("csv").reader((out / "table.csv").open()))
    assert table[0] == ["model", "libri2mix/si_snr", "libri2mix/si_snri", "real/si_snr",
                        "real/si_snri"]
    by = {r[0]: r for r in table[1:]}
    assert float(by["ceiling"][2]) >= 100 and float(by["Oracle"][4]) >= 100
    assert float(by["identity"][2]) == pytest.approx(0.0, abs=1e-6)
    assert by["partial"][1:3] == ["", ""] and float(by["partial"][4]) == pytest.approx(0, abs=1e-6)
    # Each cell's scores are kept, the per-target rows of the set's own groups.
    cell = (out / "ceiling" / "libri2mix" / "scores.csv").read_text().splitlines()
    assert cell[1].startswith("estimates,test/1089-134686-0000_121-121726-0000,mix_both,")
    assert len(cell) == 1 + 2 * 2


@pytest.mark.parametrize(("argv", "message"), [
    (["--sets", "a=x"], "--estimates-root and --sets go together"),
    (["--estimates-root", "E", "--sets", "a=x,a=y"], "the name 'a' is given twice"),
    (["--estimates-root", "E", "--sets", "a=x@"], r"nothing after '@'"),
    (["--estimates-root", "E", "--sets", "a=x,"], "an empty entry"),
    (["--estimates-root", "NOPE", "--sets", "a=x"], "NOPE: no such estimates folder"),
    (["--estimates-root", "E", "--sets", "b=DATA"], "no model has a folder for any of the "
     "sets ['b']"),
    (["--estimates-root", "E", "--sets", "m=DATA", "--oracle", "CLASH"],
     "a model folder may not be named 'Oracle'"),
    (["DATA", "--estimates-root", "E", "--sets", "a=x"], "with --sets, give no DATASET"),
])
def test_cross_set_arguments_are_checked(tmp_path: Path, capsys, argv: list[str],
                                         message: str) -> None:
    from sonicspec.cli import main

    (tmp_path / "E" / "m").mkdir(parents=True)
    if "CLASH" in argv:
        argv.remove("CLASH")
        (tmp_path / "E" / "Oracle").mkdir()
    lc.plain(tmp_path / "DATA")
    where = {"E": str(tmp_path / "E"), "DATA": str(tmp_path / "DATA")}
    argv = [where.get(a, a) for a in argv]
    argv = [a.replace("=DATA", f"={tmp_path / 'DATA'}") for a in argv]
    code = main(["evaluate", "--split", "test", "--task", "separation", *argv])
    assert code == 2
    assert message in capsys.readouterr().err


def test_cli_scores_a_public_set_with_one_command(tmp_path: Path, capsys) -> None:
    import json

    from sonicspec.cli import main

    lc.wham(tmp_path, reverb=True)
    root = tmp_path / "whamr"
    _estimates(root, tmp_path / "est", "test", "separation", "ceiling", ("mix_both_reverb",))
    out = tmp_path / "eval"
    code = main(["evaluate", str(root), "--split", "test", "--task", "separation",
                 "--format", "wham", "--mixture", "mix_both_reverb", "--estimates",
                 str(tmp_path / "est"), "--metrics", "si_snr", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["format"] == "wham"
    assert summary["per_method"]["estimates"]["targets"] == 2 * 2
    assert summary["per_method"]["estimates"]["si_snr"] >= 100.0
    # The anechoic sources are the targets; the reverberant mixture scored against them.
    lines = (out / "scores.csv").read_text().splitlines()
    assert lines[1].startswith(f"estimates,tt/{lc.WSJ_NAMES[0]},mix_both_reverb,source1,")
