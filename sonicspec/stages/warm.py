"""Compile the numba kernels once, before the first wave of jobs.

A job that finds numba's cache cold compiles every kernel it calls (seconds per job); a
hundred cluster jobs starting at once would each compile them, and write the same cache files
together. :func:`warm` runs, in one process, what the ``rir`` and ``render`` jobs run — a
traced shoebox's RIRs along a short walk and the walk rendered from its paths and late part
— on tiny inputs of the dtypes the jobs use, so the kernels are compiled into the cache
(``sonicspec.numba_cache_dir()``) once. ``sonicspec build`` calls :func:`warm_once` before it
starts Snakemake when ``rir`` or ``render`` jobs are to run; a stamp in the cache folder (named
after the package version, numba's version and the kernel sources' sizes and times) makes
every later call a ``stat``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import sonicspec
from sonicspec.hashing import sha256_hex

STEPS_THAT_COMPILE = ("rir", "render")


def _stamp() -> Path:
    import importlib.metadata

    root = Path(sonicspec.__file__).resolve().parent
    kernels = sorted(root.rglob("*kernels*.py"))
    parts = [sonicspec.__version__, importlib.metadata.version("numba")]
    for path in kernels:
        st = path.stat()
        parts.append(f"{path.relative_to(root)}|{st.st_size}|{st.st_mtime_ns}")
    digest = sha256_hex("\n".join(parts))[:16]
    return Path(sonicspec.numba_cache_dir()) / f"sonicspec-warm-{digest}"


def warm() -> None:
    """Run the rir and render kernels on tiny inputs (compiling them into the cache)."""
    import numpy as np

    from sonicspec.acoustics.bands import OctaveFilterBank
    from sonicspec.acoustics.engine import acoustic_scene, simulate_rirs
    from sonicspec.acoustics.moving.delays import PathSet, render_paths
    from sonicspec.api import RirSettings, Scene
    from sonicspec.audio.render import INTERPOLATIONS, render_moving

    fs = 16000
    room = Scene.shoebox([4.0, 3.0, 2.5])
    settings = RirSettings(rays=500, image_source_order=2, max_rir_length_s=0.2,
                           sample_rate_hz=fs).simulation_settings()
    scene = acoustic_scene(room.mesh, room.library, settings)
    points = np.array([[1.0, 1.0, 1.5], [1.25, 1.0, 1.5], [1.5, 1.0, 1.5]])
    rirs, facts = simulate_rirs(scene, np.array([3.0, 2.0, 1.2]), points, settings,
                                np.random.default_rng(0), keep_arrivals=True)
    paths = PathSet.identify(points, [f.early_arrivals for f in facts])
    dry = np.random.default_rng(1).standard_normal(fs // 4)
    index = np.linspace(0.0, len(points) - 1.0, len(dry))
    bank = OctaveFilterBank(fs, settings.bands_hz)
    render_paths(dry, index, points, paths, bank, n_out=len(dry) + 400)
    stack = np.stack([np.atleast_2d(r) for r in rirs]).astype(np.float64)
    for method in INTERPOLATIONS:
        render_moving(dry, stack, index, method)


def warm_once(stream=None) -> float | None:
    """:func:`warm` in a child process unless the cache is known warm; its seconds, or None
    when it was not needed. A failure is reported, never fatal: the jobs compile for
    themselves."""
    stamp = _stamp()
    if stamp.is_file():
        return None
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-c", "from sonicspec.stages.warm import warm; warm()"],
                          capture_output=True, text=True, env=dict(os.environ))
    seconds = time.monotonic() - start
    if done.returncode != 0:
        if stream is not None:
            tail = (done.stderr.strip().splitlines() or ["?"])[-1]
            print(f"compiling the kernels before the jobs failed ({tail}); each job compiles "
                  "what it needs", file=stream)
        return seconds
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.touch()
    if stream is not None:
        print(f"compiled the numba kernels into {stamp.parent} in {seconds:.0f} s (once)",
              file=stream)
    return seconds
