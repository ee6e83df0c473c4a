"""The real-recording kit: ``sonicspec playback`` (the playback sheet of a split) and
``sonicspec align`` (recordings of it, aligned and cut into the ``plain`` layout that
``sonicspec evaluate --format plain`` scores; sonicspec.dataload.recording)."""

from __future__ import annotations

import argparse
import sys

from sonicspec.cli.common import EXIT_INVALID, EXIT_OK


def cmd_playback(args: argparse.Namespace) -> int:
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.recording import write_sheet

    try:
        manifest = write_sheet(args.dataset, args.out, args.split)
    except DatasetError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    takes = manifest["takes"]
    seconds = sum(t["layout_samples"][k] for t in takes for k in ("lead", "chirp", "gap",
                  "content", "gap", "chirp", "tail")) / takes[0]["sample_rate_hz"]
    speakers = max(len(t["loudspeakers"]) for t in takes)
    print(f"{args.out}: {len(takes)} take(s) of split {args.split!r}, up to {speakers} "
          f"loudspeaker(s), {seconds:.1f} s to play; schedule.csv, manifest.json; record "
          "each take to RECORDINGS/<group>.wav, then `sonicspec align`")
    return EXIT_OK


def cmd_align(args: argparse.Namespace) -> int:
    from sonicspec.dataload.folder import DatasetError
    from sonicspec.dataload.recording import align

    try:
        done = align(args.recordings, args.sheet, args.out)
    except DatasetError as exc:
        print(f"sonicspec: error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    for a in done:
        print(f"{a.group}: start chirp at {a.start_chirp:.2f} samples, drift "
              f"{a.drift_ppm:+.2f} ppm, correlation {a.correlation:.2f}")
    print(f"{args.out}: {len(done)} item(s) in the plain layout (alignment.json); score with "
          f"`sonicspec evaluate {args.out} --format plain --split <split> --task ...`")
    return EXIT_OK


def add_playback(sub) -> None:
    """``sonicspec playback DATASET --out DIR``."""
    p = sub.add_parser("playback", help="write the playback sheet of a split for a real "
                       "recording: each group's dry talkers as loudspeaker WAVs between two "
                       "sync chirps, schedule.csv and manifest.json")
    p.add_argument("dataset", metavar="DATASET",
                   help="a built dataset folder with dry stems (mixture.targets: [dry])")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the sheet folder: <DIR>/<group>/loudspeaker<k>.wav (and the "
                   "references s<k>.wav), schedule.csv, manifest.json")
    p.add_argument("--split", default="test", help="the split to play (default: test)")
    p.set_defaults(func=cmd_playback)


def add_align(sub) -> None:
    """``sonicspec align RECORDINGS --sheet DIR --out DIR``."""
    p = sub.add_parser("align", help="find the sync chirps in recordings of a playback sheet, "
                       "correct the clock drift and cut them into the plain layout "
                       "(<split>/<item>/mixture.wav + s<k>.wav) for `sonicspec evaluate`")
    p.add_argument("recordings", metavar="RECORDINGS",
                   help="a folder with one recording per take: <RECORDINGS>/<group>.wav "
                   "(any channel count, at the sheet's sample rate)")
    p.add_argument("--sheet", required=True, metavar="DIR",
                   help="the folder `sonicspec playback` wrote")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the plain-layout folder to write (and alignment.json: each take's "
                   "chirp positions, drift and correlation)")
    p.set_defaults(func=cmd_align)
