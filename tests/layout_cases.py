"""Tiny folders in each external layout sonicspec reads, with the file and folder names and
the metadata CSVs their recipes write (the sources are in each reader's docstring), and short
generated audio: each writer returns ``{group id: {track or mixture name: file}}`` so a test
can read the files directly."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import soundfile as sf


def signal(rng: np.random.Generator, n: int, rate: int) -> np.ndarray:
    """A voiced-speech-like signal: harmonics of a gliding pitch under a syllable envelope."""
    t = np.arange(n) / rate
    f0 = rng.uniform(100, 220) * (1 + 0.1 * np.sin(2 * np.pi * rng.uniform(0.5, 2) * t))
    phase = 2 * np.pi * np.cumsum(f0) / rate
    x = sum(np.sin(k * phase) / k for k in range(1, 8))
    env = 0.5 * (1 + np.sin(2 * np.pi * rng.uniform(2, 5) * t + rng.uniform(0, 6)))
    return 0.2 * x * env / np.max(np.abs(x))


def write(path: Path, x: np.ndarray, rate: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    sf.write(str(path), x.astype(np.float64), rate, subtype="PCM_16")
    return path


def _sources(seed: int, k: int, n: int, rate: int, noise: bool = True):
    rng = np.random.default_rng(seed)
    s = [signal(rng, n, rate) for _ in range(k)]
    return s, (0.05 * rng.standard_normal(n) if noise else None)


def librimix(root: Path, n_src: int = 2, rate: int = 8000, mode: str = "min",
             ids: tuple[str, ...] = ("1089-134686-0000_121-121726-0000",
                                     "1221-135766-0001_2961-961-0002"),
             split: str = "test", n: int = 8000) -> dict[str, dict[str, Path]]:
    """``Libri<n>Mix/wav<k>k/<mode>`` with ``metadata/mixture_<split>_<type>.csv`` whose paths
    are another machine's (as the recipe leaves them) and ``<split>/<type>/<id>.wav``."""
    base = root / f"Libri{n_src}Mix" / f"wav{rate // 1000}k" / mode
    elsewhere = f"/home/someone/LibriMix/Libri{n_src}Mix/wav{rate // 1000}k/{mode}/{split}"
    out: dict[str, dict[str, Path]] = {}
    rows: dict[str, list[list[str]]] = {"mix_clean": [], "mix_both": [], "mix_single": []}
    for i, mid in enumerate(ids):
        s, noise = _sources(i, n_src, n, rate)
        files = {f"source{k + 1}": write(base / split / f"s{k + 1}" / f"{mid}.wav", s[k], rate)
                 for k in range(n_src)}
        files["noise"] = write(base / split / "noise" / f"{mid}.wav", noise, rate)
        files["mix_clean"] = write(base / split / "mix_clean" / f"{mid}.wav", sum(s), rate)
        files["mix_both"] = write(base / split / "mix_both" / f"{mid}.wav", sum(s) + noise,
                                  rate)
        files["mix_single"] = write(base / split / "mix_single" / f"{mid}.wav", s[0] + noise,
                                    rate)
        srcs = [f"{elsewhere}/s{k + 1}/{mid}.wav" for k in range(n_src)]
        rows["mix_clean"].append([mid, f"{elsewhere}/mix_clean/{mid}.wav", *srcs, str(n)])
        rows["mix_both"].append([mid, f"{elsewhere}/mix_both/{mid}.wav", *srcs,
                                 f"{elsewhere}/noise/{mid}.wav", str(n)])
        rows["mix_single"].append([mid, f"{elsewhere}/mix_single/{mid}.wav", srcs[0],
                                   f"{elsewhere}/noise/{mid}.wav", str(n)])
        out[f"{split}/{mid}"] = files
    src_cols = [f"source_{k + 1}_path" for k in range(n_src)]
    heads = {"mix_clean": ["mixture_ID", "mixture_path", *src_cols, "length"],
             "mix_both": ["mixture_ID", "mixture_path", *src_cols, "noise_path", "length"],
             "mix_single": ["mixture_ID", "mixture_path", "source_1_path", "noise_path",
                            "length"]}
    (base / "metadata").mkdir(parents=True, exist_ok=True)
    for kind, head in heads.items():
        with (base / "metadata" / f"mixture_{split}_{kind}.csv").open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(head)
            w.writerows(rows[kind])
    return out


WSJ_NAMES = ("011a0101_0.061105_401c020r_-0.061105", "01aa010k_1.3053_01po0310_-1.3053")


def wham(root: Path, reverb: bool = False, rate: int = 8000, mode: str = "min",
         split: str = "tt", n: int = 8000) -> dict[str, dict[str, Path]]:
    """``wham_mix/wav8k/min/tt/{mix_clean,mix_both,mix_single,s1,s2,noise}/<name>.wav``, or
    WHAMR!'s ``*_anechoic`` / ``*_reverb`` folders."""
    base = root / ("whamr" if reverb else "wham_mix") / f"wav{rate // 1000}k" / mode / split
    out = {}
    for i, name in enumerate(WSJ_NAMES):
        s, noise = _sources(10 + i, 2, n, rate)
        files = {"noise": write(base / "noise" / f"{name}.wav", noise, rate)}
        if reverb:
            rng = np.random.default_rng(20 + i)
            tail = np.exp(-np.arange(400) / 60.0) * rng.standard_normal(400) * 0.3
            tail[0] = 1.0
            r = [np.convolve(x, tail)[:n] for x in s]
            for k in (0, 1):
                files[f"source{k + 1}"] = write(base / f"s{k + 1}_anechoic" / f"{name}.wav",
                                                s[k], rate)
                files[f"source{k + 1}_reverb"] = write(
                    base / f"s{k + 1}_reverb" / f"{name}.wav", r[k], rate)
            for sfx, src in (("anechoic", s), ("reverb", r)):
                files[f"mix_clean_{sfx}"] = write(base / f"mix_clean_{sfx}" / f"{name}.wav",
                                                  src[0] + src[1], rate)
                files[f"mix_both_{sfx}"] = write(base / f"mix_both_{sfx}" / f"{name}.wav",
                                                 src[0] + src[1] + noise, rate)
                files[f"mix_single_{sfx}"] = write(
                    base / f"mix_single_{sfx}" / f"{name}.wav", src[0] + noise, rate)
        else:
            for k in (0, 1):
                files[f"source{k + 1}"] = write(base / f"s{k + 1}" / f"{name}.wav", s[k], rate)
            files["mix_clean"] = write(base / "mix_clean" / f"{name}.wav", s[0] + s[1], rate)
            files["mix_both"] = write(base / "mix_both" / f"{name}.wav", s[0] + s[1] + noise,
                                      rate)
            files["mix_single"] = write(base / "mix_single" / f"{name}.wav", s[0] + noise,
                                        rate)
        out[f"{split}/{name}"] = files
    return out


def lrs2mix(root: Path, split: str = "tt", n: int = 32000) -> dict[str, dict[str, Path]]:
    """``LRS2-2Mix/tt/{mix,s1,s2}/<name>.wav`` at 16 kHz, 2 s."""
    base = root / "LRS2-2Mix" / split
    out = {}
    for i, name in enumerate(("6330311066473698535_00011_0.53084_6339356267468615354_00010"
                              "_-0.53084",
                              "6382870262046380829_00005_2.1196_6366908211536718584_00021"
                              "_-2.1196")):
        s, _ = _sources(30 + i, 2, n, 16000, noise=False)
        out[f"{split}/{name}"] = {
            "source1": write(base / "s1" / f"{name}.wav", s[0], 16000),
            "source2": write(base / "s2" / f"{name}.wav", s[1], 16000),
            "mix": write(base / "mix" / f"{name}.wav", s[0] + s[1], 16000)}
    return out


def voicebank(root: Path, n: int = 16000) -> dict[str, dict[str, Path]]:
    """``clean_testset_wav/p232_001.wav`` + ``noisy_testset_wav/p232_001.wav`` (the 16 kHz
    copy most papers use: same names)."""
    out = {}
    for i, name in enumerate(("p232_001", "p257_014")):
        s, noise = _sources(40 + i, 1, n, 16000)
        out[f"test/{name}"] = {
            "source1": write(root / "clean_testset_wav" / f"{name}.wav", s[0], 16000),
            "noisy": write(root / "noisy_testset_wav" / f"{name}.wav", s[0] + noise, 16000)}
    return out


def dns(root: Path, n: int = 16000) -> dict[str, dict[str, Path]]:
    """``test_set/synthetic/{no_reverb,with_reverb}/{clean,noisy}`` with the fileid names."""
    out = {}
    noisy_names = {0: "clnsp102_traffic_248091_3_snr0_tl-21_fileid_0",
                   17: "clnsp52_amMeH4u6AO4_snr5_tl-18_fileid_17"}
    for c, cond in enumerate(("no_reverb", "with_reverb")):
        base = root / "test_set" / "synthetic" / cond
        for fid, noisy in noisy_names.items():
            s, noise = _sources(50 + fid + c, 1, n, 16000)
            out[f"{cond}/fileid_{fid}"] = {
                "source1": write(base / "clean" / f"clean_fileid_{fid}.wav", s[0], 16000),
                "noisy": write(base / "noisy" / f"{noisy}.wav", s[0] + noise, 16000)}
    return out


def sonicset(root: Path, n: int = 16000) -> dict[str, dict[str, Path]]:
    """The released benchmarks: ``test-noise/noise-0-1/<scene>/<group>/{mix,s1,s2}.wav`` and
    ``enh-test-noise/noise-0/<scene>/<group>/{mix,clean}.wav``."""
    out = {}
    scene, group = "2t7WUuJeko7", "0"
    for i, comb in enumerate(("0-1", "0-2")):
        folder = root / "test-noise" / f"noise-{comb}" / scene / group
        s, noise = _sources(60 + i, 2, n, 16000)
        out[f"test-noise/noise-{comb}/{scene}/{group}"] = {
            "source1": write(folder / "s1.wav", s[0], 16000),
            "source2": write(folder / "s2.wav", s[1], 16000),
            "mix": write(folder / "mix.wav", s[0] + s[1] + noise, 16000)}
    for i, spk in enumerate(("0", "1")):
        folder = root / "enh-test-noise" / f"noise-{spk}" / scene / group
        s, noise = _sources(70 + i, 1, n, 16000)
        out[f"enh-test-noise/noise-{spk}/{scene}/{group}"] = {
            "source1": write(folder / "clean.wav", s[0], 16000),
            "mix": write(folder / "mix.wav", s[0] + noise, 16000)}
    return out


def plain(root: Path, n: int = 16000) -> dict[str, dict[str, Path]]:
    """``<root>/test/<item>/mixture.wav`` + ``s1.wav``, ``s2.wav``, ``noise.wav``."""
    out = {}
    for i, name in enumerate(("room1/take1", "room2/take1")):
        folder = root / "test" / name
        s, noise = _sources(80 + i, 2, n, 16000)
        out[f"test/{name}"] = {
            "source1": write(folder / "s1.wav", s[0], 16000),
            "source2": write(folder / "s2.wav", s[1], 16000),
            "noise": write(folder / "noise.wav", noise, 16000),
            "mixture": write(folder / "mixture.wav", s[0] + s[1] + noise, 16000)}
    return out


def sonicset_raw(root: Path, n: int = 80000) -> dict[str, dict[str, Path]]:
    """The raw released folders: ``SonicSet/scene_datasets/mp3d/test/<scene>/<a>-<b>-<c>/``
    with ``moving_audio_{1,2,3}.wav``, ``noise_audio.wav``, ``music_audio.wav`` and
    ``json_data.json`` (as SonicSim-SonicSet/SonicSet.py writes them)."""
    import json

    out = {}
    base = root / "SonicSet" / "scene_datasets" / "mp3d" / "test"
    for i, (scene, spk) in enumerate((("2t7WUuJeko7", "1089-121-1221"),
                                      ("8194nk5LbLH", "2961-237-260"))):
        folder = base / scene / spk
        s, noise = _sources(90 + i, 3, n, 16000)
        music = 0.5 * signal(np.random.default_rng(95 + i), n, 16000)
        files = {f"source{k + 1}": write(folder / f"moving_audio_{k + 1}.wav", s[k], 16000)
                 for k in range(3)}
        files["noise"] = write(folder / "noise_audio.wav", noise, 16000)
        files["music"] = write(folder / "music_audio.wav", music, 16000)
        facts = {f"source{k + 1}": {"audio": [f"{spk.split('-')[k]}-0-0000"],
                                    "start_end_points": [[0, n]], "words": ["HELLO"]}
                 for k in range(3)}
        facts["noise"] = {"audio": ["123.wav"], "start_end_points": [[0, n]]}
        facts["music"] = {"audio": ["456.mp3"], "start_end_points": [[0, n]]}
        (folder / "json_data.json").write_text(json.dumps(facts))
        out[f"test/{scene}/{spk}"] = files
    return out
