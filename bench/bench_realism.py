"""Benchmark (issue 30): what the realism of ``sonicset_realistic`` costs per group.

Two parts, each built in-process (every job of one store run with
:func:`sonicspec.stages.run_job`, timed with ``getrusage``: CPU seconds of this process and
its threads, the measure that stays meaningful on a loaded machine):

1. **Presets** (``--presets``): ``specs/sonicset.yaml`` and ``specs/sonicset_realistic.yaml``
   cut down the same way (one scan of the SonicSet fixture, ``--groups`` train groups of
   ``--seconds``, ``--rays`` rays, image sources to ``--order``, 1-2 utterances per talker,
   2 noise and 2 music clips), in four variants:

   * ``sonicset``: the paper's recipe (omni talkers, one omni capsule, point noise, the
     sample crossfade, every surface fully diffuse);
   * ``realistic``: the whole preset (speech directivity facing the walk with head turns, the
     phone's two capsules, 70 % diffuse noise, ``interpolation: paths``, measured scattering,
     the phone's response, self-noise and a codec in one group in five);
   * ``realistic, no augmentation``: the preset without its ``augmentation:`` block;
   * ``realistic, omni + point``: that, with omni talkers and point noise too (no
     ``directivity:``, no ``noise_field``): the same microphone, rendering and materials, so
     the step from it to the previous column is what directivity and the diffuse background
     cost (issue 30's bar: <= 15 % per group).

   CPU seconds per group of each per-group step (placement, arrange, rir, render, mix,
   export) and their sum.
2. **Untraced** (``--untraced``): a background heard only as a diffuse field
   (``diffuse_fraction: 1``) is not traced any more; the rir step of a shoebox spec run as
   compiled (noise untraced) and once more with the noise traced (the job without its
   ``untraced`` param, as before), per group, for a mono capsule and a 4-capsule array; and
   the group's cost over all its steps, to put the saving in proportion.

A warm-up build (one short group, not counted) compiles the numba kernels first.

Reproduce:
    nice -n 10 python bench/bench_realism.py --presets --untraced
    nice -n 10 python bench/bench_realism.py --presets --groups 2 --seconds 20   # quicker
    nice -n 10 python bench/bench_realism.py --presets --variants noaug,omni --repeat 2
"""

from __future__ import annotations

import argparse
import re
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GROUP_STEPS = ("placement", "arrange", "rir", "render", "mix", "export")


def cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _sub(text: str, old: str, new: str) -> str:
    if old not in text:
        raise SystemExit(f"bench_realism: the preset changed: {old!r} not found")
    return text.replace(old, new)


def _drop_block(text: str, key: str) -> str:
    """``text`` less the top-level YAML block ``key:`` (to the next top-level key)."""
    found = re.search(rf"^{key}:\n(?:(?:[ #].*)?\n)*?(?=^[a-z])", text, re.M)
    if not found:
        raise SystemExit(f"bench_realism: no top-level {key!r} block in the preset")
    return text.replace(found.group(0), "")


def cut(text: str, label: str, groups: int, seconds: float, rays: int, order: int) -> str:
    """A preset cut down for the bench (the same cut for every variant)."""
    for old, new in (("rays: 4000", f"rays: {rays}"),
                     ("image_source_order: 3", f"image_source_order: {order}"),
                     ("duration_s: 60.0", f"duration_s: {seconds}"),
                     ("utterance_gap_s: [0.0, 8.0]", "utterance_gap_s: [0.0, 2.0]"),
                     ("utterances_per_speaker: [3, 5]", "utterances_per_speaker: [1, 2]"),
                     ("noise_clips: [6, 8]", "noise_clips: [2, 2]"),
                     ("music_clips: [6, 8]", "music_clips: [2, 2]"),
                     ("store_dir: out/store", f"store_dir: out/store_{label}"),
                     ("subsets: {train: [train-clean-360], val: [dev-clean], test: "
                      "[test-clean]}", "subsets: {train: [train-clean-360]}")):
        text = _sub(text, old, new)
    text = text.replace("split_ratios: {train: 0.7, val: 0.2, test: 0.1}",
                        "split_ratios: {train: 1}")  # one split: every clip in it
    text = re.sub(r"^  dir: .*$", f"  dir: out/{label}", text, count=1, flags=re.M)
    found = re.search(r"^splits:\n(?:  .*\n)+", text, re.M)
    assert found
    return text.replace(found.group(0), f"splits:\n  train: {{groups: {groups}, "
                        "scenes: [\"mp3d/*\"], scene_count: 1}\n")


def variants(groups: int, seconds: float, rays: int, order: int) -> dict[str, str]:
    paper = (ROOT / "specs" / "sonicset.yaml").read_text()
    real = (ROOT / "specs" / "sonicset_realistic.yaml").read_text()
    out = {"sonicset": cut(paper, "paper", groups, seconds, rays, order),
           "realistic": cut(real, "real", groups, seconds, rays, order)}
    plain = _drop_block(out["realistic"], "augmentation")
    out["realistic, no augmentation"] = plain.replace("store_real", "store_noaug")
    omni = _drop_block(plain, "directivity")
    omni = re.sub(r"^  noise_field: .*\n", "", omni, flags=re.M)
    out["realistic, omni + point"] = omni.replace("store_real", "store_omni")
    return out


def build(folder: Path, name: str, text: str) -> dict[str, float]:
    """Every job of the spec, in plan order; CPU seconds per step."""
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec
    from sonicspec.stages import run_job

    path = folder / f"{name}.yaml"
    path.write_text(text)
    plan = compile_spec(load_spec(path))
    per_step: dict[str, float] = {}
    for job in plan.jobs:
        t0 = cpu_s()
        run_job(plan, job.key)
        per_step[job.step] = per_step.get(job.step, 0.0) + cpu_s() - t0
    return per_step


SHORT = {"paper": "sonicset", "real": "realistic", "noaug": "realistic, no augmentation",
         "omni": "realistic, omni + point"}


def presets(groups: int, seconds: float, rays: int, order: int, repeat: int = 1,
            only: list[str] | None = None) -> None:
    from sonicspec.testing.sonicset import write_sonicset_inputs

    specs = variants(groups, seconds, rays, order)
    if only:
        specs = {SHORT[k]: specs[SHORT[k]] for k in only}
    print(f"\n1. presets cut down: {groups} train group(s) of {seconds:g} s on one scan of the "
          f"SonicSet fixture, {rays} rays, image sources to order {order}; CPU s per group"
          + (f", per step the least of {repeat} builds (round robin)" if repeat > 1 else ""))
    with tempfile.TemporaryDirectory(prefix="bench_realism_") as tmp:
        folder = Path(tmp)
        write_sonicset_inputs(folder / "data", ["s0"], {"train-clean-360": 6})
        t0 = cpu_s()  # warm-up: compile the kernels on one short group, not counted
        build(folder, "warmup", cut((ROOT / "specs" / "sonicset_realistic.yaml").read_text(),
                                    "warmup", 1, 12.0, 100, 1))
        print(f"   (warm-up build: {cpu_s() - t0:.1f} s CPU, not counted)")
        results: dict[str, dict[str, float]] = {}
        for r in range(repeat):  # round robin: the machine's load falls on every variant
            for label, text in specs.items():
                name = re.sub(r"\W+", "_", label)
                text = text.replace("store_dir: out/store_", f"store_dir: out/r{r}_store_")
                per_step = build(folder, f"{name}_{r}", text)
                best = results.setdefault(label, per_step)
                for step, v in per_step.items():
                    best[step] = min(best.get(step, v), v)
                total = sum(per_step.get(s, 0.0) for s in GROUP_STEPS) / groups
                print(f"   built {label!r} ({r + 1}/{repeat}): {total:.2f} s CPU per group",
                      flush=True)
    labels = list(results)
    width = max(len(s) for s in labels) + 2
    print(f"\n{'step':>10} " + "".join(f"{lab:>{width}}" for lab in labels))
    for step in GROUP_STEPS:
        print(f"{step:>10} " + "".join(f"{results[lab].get(step, 0.0) / groups:>{width - 1}.2f}s"
                                       for lab in labels))
    totals = {lab: sum(results[lab].get(s, 0.0) for s in GROUP_STEPS) / groups
              for lab in labels}
    print(f"{'per group':>10} " + "".join(f"{totals[lab]:>{width - 1}.2f}s" for lab in labels))
    print(f"{'shared':>10} " + "".join(
        f"{sum(v for s, v in results[lab].items() if s not in GROUP_STEPS):>{width - 1}.2f}s"
        for lab in labels) + "   (corpus, mesh, navigation, dataset: once per build)")
    print()
    if {SHORT["noaug"], SHORT["omni"]} <= set(totals):
        print(f"   directivity + diffuse noise: "
              f"{totals[SHORT['noaug']] / totals[SHORT['omni']]:.3f}x the same preset with "
              "omni talkers and point noise (bar <= 1.15)")
    if {SHORT["real"], SHORT["noaug"]} <= set(totals):
        print(f"   augmentation: {totals[SHORT['real']] / totals[SHORT['noaug']]:.3f}x the "
              "preset without it (their jobs before export are the same: render's difference "
              "is the machine's noise)")
    if {SHORT["real"], SHORT["paper"]} <= set(totals):
        print(f"   sonicset_realistic / sonicset: "
              f"{totals[SHORT['real']] / totals[SHORT['paper']]:.3f}x")


UNTRACED_SPEC = """\
sonicspec: 1
name: bench_untraced
seed: 3
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6.0, 5.0, 3.0]
    materials: {{walls: plaster_on_brick, floor: carpet_on_concrete,
                ceiling: acoustic_ceiling_tile}}
microphone: {mic}
placement:
  source_start_distance_m: [1.0, 3.0]
  source_end_distance_m: [1.0, 3.0]
  source_travel_distance_m: [1.0, 2.5]
  noise_distance_m: [1.0, 3.0]
  music_distance_m: [1.0, 3.0]
trajectory: {{kind: shortest_path, rir_spacing_m: 0.25}}
acoustics: {{rays: {rays}, image_source_order: {order}, max_rir_length_s: auto}}
corpora:
  speech: {{kind: generated, speakers_per_split: 3, utterances_per_speaker: 3}}
  noise: {{kind: generated, clips_per_split: 3, clip_duration_s: 5.0}}
  music: {{kind: generated, clips_per_split: 3, clip_duration_s: 5.0}}
mixture:
  duration_s: {seconds}
  speakers: 2
  utterances_per_speaker: [1, 2]
  utterance_gap_s: [0.0, 1.0]
  noise_clips: [2, 3]
  music_clips: [2, 3]
  noise_field: {{field: diffuse_spherical}}
  loudness: {{speech_lufs: -24, noise_lufs: -28, music_lufs: -31}}
  tasks:
    - {{kind: enhancement, background: both}}
splits:
  train: {{groups: {groups}, scenes: [room]}}
outputs: {{dir: out, store_dir: store, manifests: [lhotse], groups_per_shard: {groups}}}
"""


def untraced(groups: int, seconds: float, rays: int, order: int) -> None:
    import dataclasses

    from sonicspec.plan.compile import compile_spec
    from sonicspec.plan.model import Job
    from sonicspec.spec import load_spec
    from sonicspec.stages import run_job

    print(f"\n2. untraced: a diffuse-only noise (diffuse_fraction 1), {groups} group(s) of "
          f"{seconds:g} s in a 6 x 5 x 3 m room (2 walking talkers, noise, music), {rays} "
          f"rays, image sources to order {order}; rir step CPU s per group")
    with tempfile.TemporaryDirectory(prefix="bench_untraced_") as tmp:  # warm-up
        path = Path(tmp) / "spec.yaml"
        path.write_text(UNTRACED_SPEC.format(mic="{kind: mono}", seconds=8.0, groups=1,
                                             rays=100, order=1))
        warm = compile_spec(load_spec(path))
        for job in warm.jobs:
            if job.step in ("corpus", "mesh", "navigation", "placement", "arrange", "rir"):
                run_job(warm, job.key)
    print(f"{'microphone':>24} {'noise traced':>13} {'untraced':>9} {'saved':>7}   "
          f"{'group':>8} {'of it':>7}   (group: all its steps, noise untraced)")
    for mic_name, mic in (("mono", "{kind: mono}"),
                          ("circular_array (4)", "{kind: circular_array, n: 4, "
                           "radius_m: 0.05}")):
        with tempfile.TemporaryDirectory(prefix="bench_untraced_") as tmp:
            path = Path(tmp) / "spec.yaml"
            path.write_text(UNTRACED_SPEC.format(mic=mic, seconds=seconds, groups=groups,
                                                 rays=rays, order=order))
            plan = compile_spec(load_spec(path))
            rir_jobs = [j for j in plan.jobs if j.step == "rir"]
            assert all(j.params.get("untraced") == ["noise"] for j in rir_jobs)
            # the same jobs without `untraced`: the noise traced, as before
            traced = [Job("rir", {k: v for k, v in j.params.items() if k != "untraced"},
                          j.inputs, f"{j.label} (noise traced)", j.paths) for j in rir_jobs]
            plan = dataclasses.replace(plan, jobs=plan.jobs + tuple(traced))
            cpu = {"untraced": 0.0, "traced": 0.0}
            for job in plan.jobs:  # what the rir jobs read
                if job.step in ("corpus", "mesh", "navigation", "placement", "arrange"):
                    run_job(plan, job.key)
            for name, jobs in (("traced", traced), ("untraced", rir_jobs)):
                for job in jobs:
                    t0 = cpu_s()
                    run_job(plan, job.key)
                    cpu[name] += cpu_s() - t0
            rest = 0.0  # the group's other steps (as built from the untraced RIRs)
            for job in plan.jobs:
                if job.step in GROUP_STEPS and job.step != "rir":
                    t0 = cpu_s()
                    run_job(plan, job.key)
                    rest += cpu_s() - t0
        t, u, r = cpu["traced"] / groups, cpu["untraced"] / groups, rest / groups
        print(f"{mic_name:>24} {t:>12.2f}s {u:>8.2f}s {(t - u) / t:>6.1%}   "
              f"{r + u:>8.2f}s {(t - u) / (r + t):>7.1%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", action="store_true", help="part 1: the preset comparison")
    parser.add_argument("--untraced", action="store_true",
                        help="part 2: a diffuse-only background's skipped RIR")
    parser.add_argument("--groups", type=int, default=3, help="train groups per build")
    parser.add_argument("--seconds", type=float, default=30.0, help="group length, s")
    parser.add_argument("--rays", type=int, default=1000)
    parser.add_argument("--order", type=int, default=2, help="image-source order")
    parser.add_argument("--repeat", type=int, default=1,
                        help="--presets: build each variant N times, round robin, and keep "
                        "each step's least CPU (the machine's load only adds)")
    parser.add_argument("--variants", default="paper,real,noaug,omni",
                        help="--presets: which, comma-separated: paper (sonicset), real "
                        "(sonicset_realistic), noaug (without augmentation), omni (without "
                        "augmentation, omni talkers, point noise)")
    args = parser.parse_args()
    if not (args.presets or args.untraced):
        parser.error("ask for --presets, --untraced or both")
    t0 = time.perf_counter()
    print("command: python bench/bench_realism.py " + " ".join(sys.argv[1:]))
    if args.untraced:
        untraced(args.groups, args.seconds, args.rays, args.order)
    if args.presets:
        only = [v.strip() for v in args.variants.split(",") if v.strip()]
        bad = [v for v in only if v not in SHORT]
        if bad:
            parser.error(f"--variants: expected names from {', '.join(SHORT)}, got {bad[0]!r}")
        presets(args.groups, args.seconds, args.rays, args.order, args.repeat, only)
    print(f"\nwall {time.perf_counter() - t0:.1f} s, CPU {cpu_s():.1f} s")


if __name__ == "__main__":
    main()
