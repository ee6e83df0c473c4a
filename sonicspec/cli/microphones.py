"""``sonicspec microphones``: the device presets (their capsules, aperture and the source of
their geometry), and a picture of one's layout."""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from pathlib import Path

from sonicspec.cli.common import EXIT_INVALID, EXIT_OK, plot_unavailable


def device_rows() -> list[dict]:
    """One row per preset: name, capsules, aperture (mm), body, title, source."""
    from sonicspec.acoustics.receivers.devices import device, device_names

    rows = []
    for name in device_names():
        dev = device(name)
        rows.append({"name": name, "capsules": len(dev.capsules),
                     "aperture_mm": round(dev.aperture_m * 1000.0, 1), "body": dev.body,
                     "title": dev.title, "source": dev.source})
    return rows


def cmd_microphones(args: argparse.Namespace) -> int:
    from sonicspec.acoustics.receivers.devices import device_names

    if args.plot is not None:
        name, out = args.plot
        if name not in device_names():
            print(f"sonicspec: error: --plot: expected a device among "
                  f"{', '.join(device_names())}, got {name!r}", file=sys.stderr)
            return EXIT_INVALID
        if plot_unavailable(args):
            return EXIT_INVALID
        from sonicspec.export.plots import plot_device_layout

        print(f"wrote {plot_device_layout(name, Path(out))}")
        return EXIT_OK
    rows = device_rows()
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    print(f"{'device':<20} {'capsules':>8} {'aperture':>10}  body")
    for r in rows:
        print(f"{r['name']:<20} {r['capsules']:>8} {r['aperture_mm']:>7.1f} mm  {r['body']}")
    print("\nuse one in a spec as  microphone: {kind: device, device: NAME}\n\nsources:")
    for r in rows:
        print(textwrap.fill(f"{r['name']} ({r['title']}): {r['source']}", width=100,
                            initial_indent="  ", subsequent_indent="    "))
    return EXIT_OK


def add_microphones(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "microphones", help="list the microphone device presets, or draw one's layout",
        description="The device presets a spec can name (microphone: {kind: device, device: "
        "NAME}): capsules, aperture (the largest distance between two capsules), body (free "
        "field or a rigid sphere) and the datasheet or drawing each geometry comes from.")
    p.add_argument("--plot", nargs=2, metavar=("NAME", "OUT.png"),
                   help="draw the capsule layout of device NAME (from above and from the side) "
                   "into OUT.png")
    p.add_argument("--json", action="store_true",
                   help="print the presets as a JSON list (name, capsules, aperture_mm, body, "
                   "title, source)")
    p.set_defaults(func=cmd_microphones)
