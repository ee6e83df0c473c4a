"""The README's screenshot of the dataset report (docs/report.png), made from a built dataset.

Writes the report of DATASET (default: the demo, ``sonicspec build specs/demo.yaml`` first)
into a temporary folder, opens it in headless Chromium (Debian's ``chromium`` through
playwright, as the tests do), shows the distributions, and saves the view as a 256-colour PNG
(small enough to check in).

Reproduce:
    sonicspec build specs/demo.yaml --cores 2
    python bench/report_screenshot.py                 # -> docs/report.png
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", nargs="?", type=Path, default=ROOT / "specs/out/demo")
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "docs/report.png")
    parser.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = parser.parse_args()
    from PIL import Image
    from playwright.sync_api import sync_playwright

    from sonicspec.export.report import write_report

    if not (args.dataset / "dataset.json").is_file():
        raise SystemExit(f"{args.dataset}: not a built dataset; run "
                         "`sonicspec build specs/demo.yaml --cores 2` first")
    with tempfile.TemporaryDirectory() as tmp:
        report = write_report(args.dataset, Path(tmp) / "report.html", group_pages=2)
        shot = Path(tmp) / "shot.png"
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=args.chromium, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1180, "height": 940})
            page.goto(report.path.as_uri())
            page.wait_for_load_state("load")
            page.evaluate("document.getElementById('distributions').scrollIntoView()")
            page.screenshot(path=str(shot))
            browser.close()
        image = Image.open(shot).convert("RGB").quantize(colors=256, method=Image.MEDIANCUT)
        args.output.parent.mkdir(parents=True, exist_ok=True)
        image.save(args.output, optimize=True)
    print(f"wrote {args.output} ({args.output.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
