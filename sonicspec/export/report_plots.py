"""The report's pictures: matplotlib figures rendered to SVG and embedded as data URIs.

Static SVG keeps the page self-contained with no JavaScript library (an interactive library
inlines 1-4 MB of script into every page), small (a histogram is ~15 kB), sharp at any zoom,
and fast to make (~20 ms a figure, so hundreds of group pages take seconds). Figures are made
with ``matplotlib.figure.Figure`` (no pyplot state), and the SVG is deterministic (a fixed hash
salt, no date).
"""

from __future__ import annotations

import base64
import io
import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from sonicspec.errors import SonicspecError

SPLIT_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
RANGE_COLORS = {"spec": "#2ca02c", "paper": "#9467bd"}


def _figure(width: float, height: float, margins: tuple[float, float, float, float] = (
        0.13, 0.97, 0.16, 0.93)):
    """A figure with fixed margins (left, right, bottom, top): a layout engine would cost
    more than the drawing."""
    try:
        import matplotlib
        from matplotlib.figure import Figure
    except ImportError:
        raise SonicspecError("the report needs matplotlib: pip install 'sonicspec[report]'"
                             ) from None
    matplotlib.rcParams["svg.hashsalt"] = "sonicspec-report"
    matplotlib.rcParams["svg.fonttype"] = "none"  # text as text: a third of the bytes
    fig = Figure(figsize=(width, height))
    left, right, bottom, top = margins
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, wspace=0.3)
    return fig


def svg_uri(fig) -> str:
    """The figure as a ``data:image/svg+xml;base64,...`` URI."""
    buf = io.BytesIO()
    fig.savefig(buf, format="svg", metadata={"Date": None})
    return "data:image/svg+xml;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def histogram(per_split: Mapping[str, np.ndarray], label: str, unit: str, *,
              marks: Sequence[tuple[str, float]] = (),
              ranges: Sequence[tuple[str, float, float]] = ()) -> str:
    """Step histograms of one quantity, one per split (share of the split's values), with
    recipe ranges shaded and marks drawn as dashed lines."""
    fig = _figure(4.6, 2.8)
    ax = fig.subplots()
    finite = [v for v in per_split.values() if v.size]
    if finite:
        allv = np.concatenate(finite)
        lo, hi = float(allv.min()), float(allv.max())
        if hi - lo < 1e-9:
            lo, hi = lo - 0.5, hi + 0.5
        bins = np.linspace(lo, hi, 31)
        for k, (split, v) in enumerate(per_split.items()):
            if v.size:
                ax.hist(v, bins=bins, weights=np.full(v.size, 1.0 / v.size), histtype="step",
                        lw=1.5, color=SPLIT_COLORS[k % len(SPLIT_COLORS)],
                        label=f"{split} (n={v.size})")
    else:
        ax.text(0.5, 0.5, "no values", ha="center", va="center", transform=ax.transAxes)
    for name, lo_r, hi_r in ranges:
        ax.axvspan(lo_r, hi_r, color=RANGE_COLORS.get(name, "grey"), alpha=0.10,
                   label=f"{name} range {lo_r:g}–{hi_r:g}")
    for k, (name, value) in enumerate(marks):
        ax.axvline(value, color=("#9467bd", "#2ca02c", "#d62728")[k % 3], ls="--", lw=1.2,
                   label=f"{name}: {value:g}")
    ax.set_xlabel(f"{label} ({unit})" if unit else label, fontsize=8)
    ax.set_ylabel("share", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6.5, loc="best", framealpha=0.8)
    return svg_uri(fig)


def shares(per_split: Mapping[str, Mapping[str, float]], title: str) -> str:
    """Stacked horizontal bars: the share of each category per split."""
    height = 0.9 + 0.4 * max(1, len(per_split))
    fig = _figure(4.6, height, (0.16, 0.97, 0.55 / height, 1 - 0.35 / height))
    ax = fig.subplots()
    kinds = sorted({k for v in per_split.values() for k in v})
    splits = list(per_split)
    left = np.zeros(len(splits))
    for k, kind in enumerate(kinds):
        w = np.asarray([per_split[s].get(kind, 0.0) for s in splits])
        ax.barh(splits, w, left=left, color=f"C{k}", label=kind)
        left += w
    ax.set_xlim(0, 1)
    ax.set_xlabel(title, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6.5, ncol=max(1, len(kinds)), loc="lower center",
              bbox_to_anchor=(0.5, 1.0), frameon=False)
    return svg_uri(fig)


def per_band(per_split: Mapping[str, np.ndarray], bands_hz: Sequence[float], label: str,
             unit: str) -> str:
    """Median and 5–95 % range per octave band, one line per split. ``per_split``: (n, bands)."""
    fig = _figure(4.6, 2.8)
    ax = fig.subplots()
    x = np.arange(len(bands_hz))
    for k, (split, v) in enumerate(per_split.items()):
        if not v.size:
            continue
        color = SPLIT_COLORS[k % len(SPLIT_COLORS)]
        with warnings.catch_warnings():  # a band with no figure (all NaN) draws nothing
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(v, axis=0)
            lo, hi = np.nanpercentile(v, 5, axis=0), np.nanpercentile(v, 95, axis=0)
        ax.plot(x, med, "o-", color=color, lw=1.5, ms=4, label=f"{split} (n={len(v)})")
        ax.fill_between(x, lo, hi, color=color, alpha=0.15)
    ax.set_xticks(x, [f"{b:g}" for b in bands_hz])
    ax.set_xlabel("octave band (Hz)", fontsize=8)
    ax.set_ylabel(f"{label} ({unit})", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6.5, loc="best")
    return svg_uri(fig)


def floor_plan(walls: Sequence[np.ndarray], paths: Sequence[np.ndarray],
               mics: np.ndarray, statics: np.ndarray, *, title: str,
               bounds: tuple[np.ndarray, np.ndarray] | None = None,
               labels: Sequence[str] | None = None,
               mic_paths: Sequence[np.ndarray] = ()) -> str:
    """Walls (segments cut from the mesh), every path (start o, end ■), microphones (▲ where
    they start, a moving one's walk dashed to its end ▼) and static sources (x). With many
    paths they are drawn as one raster layer inside the SVG."""
    from matplotlib.collections import LineCollection

    fig = _figure(5.0, 4.2, (0.12, 0.98, 0.11, 0.93))
    ax = fig.subplots()
    wall_segments = np.concatenate(walls) if len(walls) else np.zeros((0, 2, 2))
    if len(wall_segments):
        ax.add_collection(LineCollection(wall_segments, colors="black", linewidths=1.4))
    many = len(paths) > 60  # drawn thin and light, without labels
    raster = len(paths) > 3000  # a few polylines each: vector up to here (~0.5 MB)
    if paths:
        if labels is not None and not many:
            for k, p in enumerate(paths):
                ax.plot(p[:, 0], p[:, 1], "-", color=f"C{k}", lw=1.8, label=labels[k])
                ax.plot(p[0, 0], p[0, 1], "o", color=f"C{k}", ms=6)
                ax.plot(p[-1, 0], p[-1, 1], "s", color=f"C{k}", ms=6)
        else:
            lines = LineCollection([p[:, :2] for p in paths], colors="C0",
                                   linewidths=0.8 if many else 1.4, alpha=0.35 if many else 0.8,
                                   rasterized=raster)
            ax.add_collection(lines)
            starts = np.asarray([p[0, :2] for p in paths])
            ends = np.asarray([p[-1, :2] for p in paths])
            ax.plot(starts[:, 0], starts[:, 1], "o", color="C0", ms=2.5, rasterized=raster)
            ax.plot(ends[:, 0], ends[:, 1], "s", color="C1", ms=2.5, rasterized=raster)
    if len(statics):
        ax.plot(statics[:, 0], statics[:, 1], "x", color="dimgray", ms=6, ls="none",
                label="noise / music", rasterized=raster)
    if len(mics):
        ax.plot(mics[:, 0], mics[:, 1], "^", color="crimson", ms=8 if len(mics) < 20 else 4,
                ls="none", label="microphone", rasterized=raster)
    for k, walk in enumerate(mic_paths):
        ax.plot(walk[:, 0], walk[:, 1], "--", color="crimson", lw=1.2, rasterized=raster,
                label="microphone's walk" if k == 0 else None)
        ax.plot(walk[-1, 0], walk[-1, 1], "v", color="crimson", ms=6, rasterized=raster)
    points = [a for a in (wall_segments.reshape(-1, 2), *(w[:, :2] for w in mic_paths),
                          *(p[:, :2] for p in paths), mics[:, :2] if len(mics) else None,
                          statics[:, :2] if len(statics) else None) if a is not None and len(a)]
    if bounds is not None:
        lo, hi = bounds
    elif points:
        allp = np.concatenate(points)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
    else:
        lo, hi = np.zeros(2), np.ones(2)
    ax.set_xlim(lo[0] - 0.3, hi[0] + 0.3)
    ax.set_ylim(lo[1] - 0.3, hi[1] + 0.3)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=6.5, loc="upper right", framealpha=0.8)
    return svg_uri(fig)


def rirs_and_edcs(rirs: Mapping[str, np.ndarray], sample_rate_hz: float) -> str:
    """A group's RIRs (one per source, at its first point): their level envelope and their
    broadband energy decay curves (Schroeder), all sources in one figure."""
    from sonicspec.acoustics.metrics import edc_db, onset_index

    fig = _figure(6.6, 2.7, (0.08, 0.98, 0.17, 0.9))
    ax_w, ax_e = fig.subplots(1, 2)
    for k, (name, rir) in enumerate(rirs.items()):
        x = np.asarray(rir, dtype=np.float64)
        color = f"C{k}"
        # Thousands of samples: their peak level per column of ~300, in dB re the peak.
        step = max(1, x.size // 300)
        cols = np.abs(x[: x.size // step * step]).reshape(-1, step).max(axis=1)
        level = 20 * np.log10(np.maximum(cols, 1e-12) / max(float(np.abs(x).max()), 1e-12))
        ax_w.plot(np.arange(cols.size) * step / sample_rate_hz, level, lw=0.8, color=color,
                  label=name)
        start = onset_index(x)
        curve = edc_db(x[start:] ** 2, sample_rate_hz)
        # A decay curve is smooth: 150 points draw it as exactly as the page shows it.
        keep = np.unique(np.linspace(0, curve.size - 1, 150).astype(int))
        ax_e.plot(keep / sample_rate_hz, curve[keep], lw=1.0, color=color, label=name)
    ax_w.set_ylim(-80, 3)
    ax_w.set_xlabel("time (s)", fontsize=8)
    ax_w.set_ylabel("level (dB re peak)", fontsize=8)
    ax_w.set_title("RIR envelopes (channel 0)", fontsize=8)
    ax_e.set_ylim(-70, 3)
    ax_e.set_xlabel("time after the direct sound (s)", fontsize=8)
    ax_e.set_title("energy decay curves (broadband)", fontsize=8)
    ax_e.legend(fontsize=6.5)
    for ax in (ax_w, ax_e):
        ax.tick_params(labelsize=7)
    return svg_uri(fig)


def directivity_polar(name: str, pattern, bands_hz: Sequence[float]) -> str:
    """A source pattern in the horizontal plane, one line per octave band (0°: where the
    source faces), dB re on-axis; ``pattern``: a
    :class:`~sonicspec.acoustics.directivity.DirectivityPattern`."""
    fig = _figure(3.4, 3.2, (0.1, 0.9, 0.1, 0.84))
    ax = fig.add_subplot(projection="polar")
    az = np.radians(np.linspace(-180.0, 180.0, 145))
    local = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], axis=1)
    gains = np.asarray(pattern.gains(local, bands_hz), dtype=np.float64)
    db = np.maximum(20.0 * np.log10(np.maximum(np.abs(gains), 1e-6)), -30.0)
    for b, f in enumerate(bands_hz):
        ax.plot(az, db[:, b] + 30.0, lw=1.2, color=f"C{b % 10}",
                label=f"{f / 1000:g} kHz" if f >= 1000 else f"{f:g} Hz")
    ax.set_ylim(0.0, 31.0)
    ax.set_yticks([10.0, 20.0, 30.0], ["-20 dB", "-10 dB", "0 dB"], fontsize=6)
    ax.set_theta_zero_location("N")
    ax.tick_params(labelsize=6.5)
    ax.set_title(f"{name} (0°: the front)", fontsize=8)
    ax.legend(fontsize=5.5, loc="lower left", bbox_to_anchor=(0.92, -0.05), frameon=False)
    return svg_uri(fig)


def device_layout(name: str) -> str:
    """A device preset's capsules from above and from the side (the drawing
    ``sonicspec microphones --plot`` makes: :func:`sonicspec.export.plots.draw_device_layout`)."""
    from sonicspec.export.plots import draw_device_layout

    fig = _figure(6.4, 3.2, (0.09, 0.98, 0.14, 0.8))
    draw_device_layout(fig, name)
    for ax in fig.axes:
        ax.title.set_fontsize(8)
        ax.xaxis.label.set_fontsize(7)
        ax.yaxis.label.set_fontsize(7)
        ax.tick_params(labelsize=6.5)
    fig._suptitle.set_fontsize(8)
    return svg_uri(fig)
