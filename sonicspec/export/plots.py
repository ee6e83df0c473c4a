"""Pictures a person wants to look at: the floor plan of a scene with a sampled group.

matplotlib is an optional dependency (``pip install 'sonicspec[plot]'``), imported only here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sonicspec.artifacts import GroupPlacement
from sonicspec.errors import SonicspecError
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.navigation import Navigation
from sonicspec.units import seconds_to_samples_floor


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise SonicspecError("plots need matplotlib: pip install 'sonicspec[plot]'") from None
    return plt


def slice_segments(mesh: SceneMesh, z_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the horizontal plane ``z = z_m`` cuts the mesh: (S, 2, 2) segments, face ids."""
    v = mesh.vertices[mesh.faces]  # (F, 3, 3)
    d = v[:, :, 2] - z_m
    above = d > 0
    crossing = above.any(axis=1) & ~above.all(axis=1)
    v, d = v[crossing], d[crossing]
    ids = np.flatnonzero(crossing)
    segments = np.zeros((len(v), 2, 2))
    for k in range(len(v)):
        points = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            if (d[k, a] > 0) != (d[k, b] > 0):
                t = d[k, a] / (d[k, a] - d[k, b])
                points.append(v[k, a, :2] + t * (v[k, b, :2] - v[k, a, :2]))
        if len(points) >= 2:
            segments[k] = points[:2]
    return segments, ids


def plot_floor_plan(mesh: SceneMesh, nav: Navigation, placement: GroupPlacement | None,
                    path: Path, *, title: str = "") -> Path:
    """Floor plan per floor: walkable area, walls, obstacles, mic, sources and their paths."""
    plt = _pyplot()  # first: without matplotlib, its message rather than an ImportError
    from matplotlib.collections import LineCollection

    n = max(1, len(nav.grids))
    fig, axes = plt.subplots(1, n, figsize=(6.5 * n, 6), squeeze=False)
    for k, ax in enumerate(axes[0]):
        if k >= len(nav.grids):
            ax.text(0.5, 0.5, "no floor found", ha="center", transform=ax.transAxes)
            continue
        grid = nav.grids[k]
        ny, nx = grid.shape
        x0, y0 = grid.origin_xy_m
        extent = (x0, x0 + nx * grid.cell_m, y0, y0 + ny * grid.cell_m)
        ax.imshow(np.where(grid.walkable, 1.0, np.nan), origin="lower", extent=extent,
                  cmap="Greens", vmin=0, vmax=2, alpha=0.6, interpolation="nearest")
        # Walls cut at 1 m; objects also at 0.25 m, so low furniture (beds, sofas) shows.
        walls, obstacles = [], []
        for dz in (1.0, 0.25):
            segments, ids = slice_segments(mesh, grid.floor.z_m + dz)
            is_object = np.zeros(len(ids), bool)
            if mesh.face_object is not None:
                is_object = mesh.face_object[ids] >= 0
            obstacles.append(segments[is_object])
            if dz == 1.0:
                walls.append(segments[~is_object])
        ax.add_collection(LineCollection(np.concatenate(walls), colors="black", linewidths=1.6,
                                         label="walls (cut at 1 m)"))
        obstacle_segments = np.concatenate(obstacles)
        if len(obstacle_segments):
            ax.add_collection(LineCollection(obstacle_segments, colors="saddlebrown",
                                             linewidths=1.2, label="obstacles"))
        if placement is not None and placement.floor_index == k:
            mic = placement.mic_m
            ax.plot(mic[0], mic[1], marker="^", color="crimson", markersize=11, ls="none",
                    label="microphone")
            for i, src in enumerate(placement.speech):
                p = np.asarray(src.path_m)
                color = f"C{i}"
                ax.plot(p[:, 0], p[:, 1], "-", color=color, lw=2, label=f"speaker {i + 1}")
                pts = np.asarray(src.rir_points_m)
                ax.plot(pts[:, 0], pts[:, 1], ".", color=color, ms=4)
                ax.plot(p[0, 0], p[0, 1], "o", color=color, ms=8)
                ax.plot(p[-1, 0], p[-1, 1], "s", color=color, ms=8)
            for kind, marker in (("noise", "X"), ("music", "P")):
                src = getattr(placement, kind)
                if src is not None:
                    ax.plot(src.start_m[0], src.start_m[1], marker=marker, color="dimgray",
                            ms=11, ls="none", label=kind)
        area = grid.area_m2
        ax.set_title(f"floor {k} (z = {grid.floor.z_m:.2f} m, walkable {area:.1f} m²)")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        ax.set_xlim(lo[0] - 0.3, hi[0] + 0.3)
        ax.set_ylim(lo[1] - 0.3, hi[1] + 0.3)
        ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    if title:
        fig.suptitle(title + ("  (o start, ■ end, · RIR points)" if placement else ""))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_rir(rir: np.ndarray, sample_rate_hz: float, bands_hz, path: Path, *, title: str = ""
             ) -> Path:
    """Waveform, energy decay curves per band, and the early arrivals' levels."""
    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.metrics import edc_db, onset_index

    plt = _pyplot()
    t = np.arange(rir.size) / sample_rate_hz
    fig, axes = plt.subplots(3, 1, figsize=(9, 9))
    axes[0].plot(t, rir, lw=0.6)
    axes[0].set_title("waveform (pressure, unit point source)")
    axes[0].set_xlabel("time (s)")
    bank = OctaveFilterBank(sample_rate_hz, tuple(bands_hz))
    start = onset_index(rir)
    for band, x in zip(bank.bands_hz, bank.split(rir), strict=True):
        curve = edc_db(x[start:] ** 2, sample_rate_hz)
        axes[1].plot(t[start:], curve, lw=1.0, label=f"{band:g} Hz")
    axes[1].set_ylim(-80, 3)
    axes[1].set_title("energy decay curves (Schroeder)")
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("dB")
    axes[1].legend(fontsize=8, ncol=3)
    early = slice(0, min(rir.size, seconds_to_samples_floor(0.1, sample_rate_hz)))
    level = 20 * np.log10(np.maximum(np.abs(rir[early]), 1e-12))
    axes[2].plot(1000 * t[early], level, lw=0.7)
    axes[2].set_ylim(level.max() - 60, level.max() + 3)
    axes[2].set_title("first 100 ms (arrivals)")
    axes[2].set_xlabel("time (ms)")
    axes[2].set_ylabel("dB")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_device_layout(fig, name: str) -> None:
    """Draw a device preset's capsules into ``fig`` (a matplotlib figure): seen from above
    (x its front, y its left) and from the side (x, z), numbered as its channels;
    directional capsules with their axes, a rigid sphere drawn as its outline. The report
    (:mod:`sonicspec.export.report_plots`) and :func:`plot_device_layout` share it."""
    from matplotlib.patches import Circle

    from sonicspec.acoustics.receivers.devices import device

    dev = device(name)
    caps = dev.capsules
    p_mm = caps.offsets_m * 1000.0
    axes = fig.subplots(1, 2)
    reach = max(float(np.abs(p_mm).max()), 5.0) * 1.3
    for ax, (i, j), label in ((axes[0], (0, 1), ("x: front (mm)", "y: left (mm)")),
                              (axes[1], (0, 2), ("x: front (mm)", "z: up (mm)"))):
        if caps.sphere_radius_m is not None:
            ax.add_patch(Circle((0, 0), caps.sphere_radius_m * 1000.0, fill=False,
                                ls="--", color="0.5", label="rigid sphere"))
        order = np.argsort(p_mm[:, 3 - i - j]) if caps.sphere_radius_m is not None else \
            np.arange(len(p_mm))
        ax.scatter(p_mm[order, i], p_mm[order, j], s=40, zorder=3, color="tab:blue")
        for m in range(len(p_mm)):
            ax.annotate(str(m + 1), (p_mm[m, i], p_mm[m, j]), textcoords="offset points",
                        xytext=(4, 4), fontsize=7)
            if caps.alphas[m] != 1.0:
                ax.annotate("", (p_mm[m, i] + 0.15 * reach * caps.axes[m, i],
                                 p_mm[m, j] + 0.15 * reach * caps.axes[m, j]),
                            (p_mm[m, i], p_mm[m, j]),
                            arrowprops={"arrowstyle": "->", "color": "tab:red"})
        ax.annotate("", (0.6 * reach, 0), (0, 0),
                    arrowprops={"arrowstyle": "-|>", "color": "0.6"})
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.set_xlabel(label[0])
        ax.set_ylabel(label[1])
    axes[0].set_title("from above")
    axes[1].set_title("from the side")
    fig.suptitle(f"{dev.name}: {dev.title}\n{len(caps)} capsules, aperture "
                 f"{dev.aperture_m * 1000:.1f} mm, {dev.body}", fontsize=10)


def plot_device_layout(name: str, path: Path) -> Path:
    """A device preset's layout (:func:`draw_device_layout`) as an image file. Written
    atomically."""
    from sonicspec.atomic import atomic_path

    plt = _pyplot()
    fig = plt.figure(figsize=(10, 5))
    draw_device_layout(fig, name)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
