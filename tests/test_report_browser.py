"""The report a build writes (``outputs.report``) of the cut-down demo, opened in headless
Chromium (Debian's ``chromium``, driven by playwright; CI installs both): no console errors,
every plot drawn with a size, the group table filters and sorts, audio loads, links resolve;
a screenshot is saved. Its figures against the metadata and the store's RIRs."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pytest

# Imported at collection: build() binds sys.stderr as its default stream when its module is
# first imported, and a first import under another test's capsys would bind a closed stream.
import sonicspec.stages.workflow  # noqa: F401
from sonicspec.cli import main
from sonicspec.export.checksums import read_checksums, unlisted_files
from sonicspec.export.report_data import StoreView, read_metadata

pytestmark = pytest.mark.slow  # one cut-down demo build (~30 s on 2 cores)

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
HAVE_BROWSER = importlib.util.find_spec("playwright") is not None and Path(CHROMIUM).is_file()


@pytest.fixture(scope="module")
def demo(tmp_path_factory, demo_reference) -> Path:
    """The cut-down demo built with ``outputs.report`` on; its dataset folder. Built on a copy
    of conftest's ``demo_reference`` (the report changes no artifact key: the build makes the
    dataset folder again, now with its report)."""
    folder = tmp_path_factory.mktemp("demo") / "b"
    shutil.copytree(demo_reference[0], folder, symlinks=True)
    spec = folder / "demo.yaml"
    text = spec.read_text()
    assert "  groups_per_shard: 2\n" in text
    spec.write_text(text.replace("  groups_per_shard: 2\n", "  groups_per_shard: 2\n"
                                 "  report: {enabled: true, group_pages: 3}\n"))
    assert main(["build", str(spec), "--cores", "2"]) == 0
    return folder / "out" / "demo"


def test_the_build_writes_the_report_outside_the_checksums(demo: Path) -> None:
    page = demo / "report.html"
    assert page.is_file()
    assert len(list((demo / "report_files" / "groups").glob("*.html"))) == 3
    assert unlisted_files(demo, read_checksums(demo)) == []  # no stray-file warning next time
    marker = json.loads((demo / ".sonicspec-dataset.json").read_text())
    text = page.read_text()
    assert f'id="content-key">{marker["dataset_key"]}<' in text
    # From the store: build facts, scene materials and repair facts, per-band figures.
    assert "<th class=\"text\">cores given</th><td class=\"text\">2</td>" in text
    living = text.split('data-scene="living_room"')[1].split('class="card scene"')[0]
    assert "<td>sofa</td>" in living and "<td>plaster_on_brick</td>" in living
    assert "none (a procedural room is watertight by construction)" in living
    for band in ("band_t30", "band_edt", "band_c50"):
        assert f'data-quantity="{band}"' in text


def test_the_group_pages_show_the_rirs_the_metadata_measured(demo: Path) -> None:
    """The report's RIR of each source is the one whose T30 the metadata holds."""
    from sonicspec.acoustics.metrics import room_acoustic_figures

    marker = json.loads((demo / ".sonicspec-dataset.json").read_text())
    view = StoreView((demo / marker["store"]).resolve(), marker["dataset_key"])
    meta = read_metadata(demo / "train" / "000000" / "metadata.json")
    rirs, info = view.first_rirs(meta["keys"]["rir"], "train/000000")
    assert set(rirs) == {"source1", "source2", "noise", "music"}
    for name, rir in rirs.items():
        figures = room_acoustic_figures(np.asarray(rir, np.float64), info["sample_rate_hz"],
                                        info["bands_hz"]).to_dict()
        for got, expected in ((figures["broadband"]["t30_s"], meta[name]["t30_s"]),
                              (figures["drr_db"], meta[name]["drr_db"])):
            # None: too short a decay for a T30 (the cut-down tracer's 0.4 s RIRs), in both
            assert got == (None if expected is None else pytest.approx(expected, rel=1e-9))


def _file_of(url: str) -> Path:
    return Path(unquote(urlparse(url).path))


def _check_page(page, errors: list[str]) -> None:
    """Every plot has a size, every link resolves (a file, or an element for #anchors)."""
    sizes = page.eval_on_selector_all(
        "img.plot", "els => els.map(e => [e.naturalWidth, e.naturalHeight, "
        "e.getBoundingClientRect().width, e.getBoundingClientRect().height])")
    assert sizes and all(min(s) > 0 for s in sizes), sizes
    links = page.eval_on_selector_all("a[href]", "els => els.map(e => [e.getAttribute('href'),"
                                      " e.href])")
    assert links
    for raw, absolute in links:
        if raw.startswith("#"):
            assert page.locator(f"[id='{raw[1:]}']").count() == 1, raw
        else:
            assert _file_of(absolute).is_file(), raw
    assert errors == []


@pytest.mark.skipif(not HAVE_BROWSER, reason="needs playwright and Debian's chromium "
                    "(pip install playwright; apt-get install chromium)")
def test_the_report_in_headless_chromium(demo: Path, tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    rows = json.loads((demo / "report.html").read_text().split('id="group-data">')[1]
                      .split("</script>")[0])
    summary = json.loads((demo / "dataset.json").read_text())
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((demo / "report.html").as_uri())
        page.wait_for_load_state("load")
        _check_page(page, errors)
        shot = tmp_path / "report.png"
        page.screenshot(path=str(shot))
        assert shot.stat().st_size > 10_000 and shot.read_bytes()[:4] == b"\x89PNG"
        print(f"screenshot: {shot}")

        body = page.locator("#group-table tbody tr")
        assert body.count() == len(rows) == len(summary["groups"])
        page.select_option("#filter-split", "train")
        train = [g["group"] for g in summary["groups"] if g["split"] == "train"]
        assert sorted(body.evaluate_all("rs => rs.map(r => r.dataset.group)")) == train
        assert page.inner_text("#group-count").startswith(f"{len(train)} of {len(rows)}")
        page.select_option("#filter-split", "")
        page.select_option("#filter-scene", "office")
        assert body.evaluate_all("rs => rs.map(r => r.dataset.scene)") == ["office"]
        page.select_option("#filter-scene", "")
        gain = {r["group"]: r["gain_db"] for r in rows}
        page.click("#group-table th[data-key='gain_db']")
        order = body.evaluate_all("rs => rs.map(r => r.dataset.group)")
        assert [gain[g] for g in order] == sorted(gain.values())
        page.click("#group-table th[data-key='gain_db']")
        order = body.evaluate_all("rs => rs.map(r => r.dataset.group)")
        assert [gain[g] for g in order] == sorted(gain.values(), reverse=True)

        page.check("#filter-pages")
        assert body.count() == 3
        page.locator("#group-table tbody tr a").first.click()
        page.wait_for_load_state("load")
        assert "/report_files/groups/" in page.url
        _check_page(page, errors)
        assert page.locator("#rir-plot").count() == 1
        audio = page.locator("audio")
        assert audio.count() == 7  # 2 sources, noise, music, 3 mixtures
        page.wait_for_function("Array.from(document.querySelectorAll('audio'))"
                               ".every(a => a.readyState >= 2)", timeout=15_000)
        page.screenshot(path=str(tmp_path / "group.png"), full_page=True)
        page.click("#back")
        page.wait_for_load_state("load")
        assert page.url.endswith("report.html#groups")
        assert errors == []
        browser.close()
