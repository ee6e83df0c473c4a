"""The real-recording kit: play a dataset's dry talkers through loudspeakers, record the room,
and cut the recordings into the ``plain`` layout so ``sonicspec evaluate`` scores them.

Two steps (docs/guide/recording.md draws the protocol):

* :func:`write_sheet` (``sonicspec playback``) writes the *playback sheet*: for each group of a
  split one *take*, ``<sheet>/<group>/loudspeaker<k>.wav`` per talker (talker ``k``'s dry
  track, the group's ``source<k>_dry`` stem), every file of a take the same length::

      | lead | sync chirp | gap | dry talker (num_samples) | gap | sync chirp | tail |

  The chirps (an exponential sweep, :class:`Chirp`) play on loudspeaker 1 only (the *sync
  loudspeaker*; the others are silent then), so a recording holds one arrival of each.
  ``schedule.csv`` says which file plays on which loudspeaker and when, ``manifest.json`` holds
  the chirp's parameters, the take's layout in samples, the gain the take was played at and
  each talker's expected position (the group's first track position, metres).
* :func:`align` (``sonicspec align``) reads each take's recording ``<recordings>/<group>.wav``,
  finds both chirps by matched filtering (the normalised cross-correlation with the known chirp,
  the peak refined to a fraction of a sample on its Hilbert envelope), measures the clock drift
  from their spacing (the recorder's samples per played sample), resamples the recording onto
  the playback clock with a windowed-sinc interpolator at the measured ratio, and cuts the
  talkers' span into ``<out>/<split>/<item>/mixture.wav`` beside the references ``s<k>.wav``
  (the dry tracks as played). The cut starts where the start chirp arrived, so the
  sync loudspeaker's acoustic delay stays in the recording as it would in any room.

Errors name the file and the value: a chirp not found (with the best normalised correlation
seen), a drift beyond :data:`MAX_DRIFT_PPM`, a recording shorter than the take.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.atomic import atomic_path, write_text
from sonicspec.dataload.folder import DatasetError, DatasetFolder

SHEET_VERSION = 1
MAX_DRIFT_PPM = 1000.0
MIN_CORRELATION = 0.1  # noise alone: at most about 0.04 over a minute (1 s sweep at 16 kHz)
PEAK_DBFS = -6.0  # the loudest sample of a take's files
SINC_HALF_TAPS = 32
PHASES = 2048  # the resampling kernel's table: fractional offsets per sample
FIRST_ARRIVAL_S = 0.02  # how far before the strongest arrival the direct sound is sought


@dataclass(frozen=True)
class Chirp:
    """The sync signal: an exponential (log) sine sweep ``f_start_hz`` → ``f_stop_hz`` over
    ``duration_s`` at ``amplitude`` (linear, full scale 1), with ``fade_s`` raised-cosine
    fades at both ends."""

    f_start_hz: float = 100.0
    f_stop_hz: float = 6000.0
    duration_s: float = 1.0
    amplitude: float = 0.5
    fade_s: float = 0.01

    def samples(self, rate: float) -> np.ndarray:
        """The sweep sampled at ``rate`` (Hz; a recorder's rate may be fractional: the
        playback rate times its drift ratio)."""
        from scipy.signal import chirp

        if not 0 < self.f_start_hz < self.f_stop_hz < rate / 2:
            raise DatasetError(f"chirp: {self.f_start_hz}–{self.f_stop_hz} Hz does not fit "
                               f"below the Nyquist frequency of {rate} Hz")
        n = round(self.duration_s * rate)
        t = np.arange(n) / rate
        x = chirp(t, self.f_start_hz, self.duration_s, self.f_stop_hz, method="logarithmic",
                  phi=-90)
        fade = round(self.fade_s * rate)
        if fade:
            ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(fade) / fade)
            x[:fade] *= ramp
            x[n - fade:] *= ramp[::-1]
        return self.amplitude * x


@dataclass(frozen=True)
class Take:
    """The layout of one take in playback samples: ``lead`` silence, the chirp (``chirp``
    samples), ``gap``, the talkers (``content``), ``gap``, the chirp, ``tail``."""

    lead: int
    chirp: int
    gap: int
    content: int
    tail: int

    @property
    def start_chirp(self) -> int:
        return self.lead

    @property
    def content_start(self) -> int:
        return self.lead + self.chirp + self.gap

    @property
    def end_chirp(self) -> int:
        return self.content_start + self.content + self.gap

    @property
    def length(self) -> int:
        return self.end_chirp + self.chirp + self.tail


def _write_wav(path: Path, x: np.ndarray, rate: int, subtype: str = "PCM_24") -> None:
    import soundfile as sf

    with atomic_path(path) as tmp:
        sf.write(str(tmp), np.asarray(x, dtype=np.float64).T, rate, subtype=subtype,
                 format="WAV")


def _read_wav(path: Path) -> tuple[np.ndarray, int]:
    import soundfile as sf

    try:
        data, rate = sf.read(str(path), dtype="float64", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, OSError) as exc:
        raise DatasetError(f"{path}: cannot read audio ({exc})") from None
    return data.T, int(rate)


def _first_position(group, name: str) -> list[float] | None:
    try:
        positions = np.asarray(group.track(name)["positions_m"], dtype=float)
    except (DatasetError, KeyError):
        return None
    return [round(float(v), 4) for v in positions.reshape(-1, 3)[0]] if positions.size else None


def write_sheet(dataset: str | Path, out: str | Path, split: str = "test", *,
                chirp: Chirp | None = None, lead_s: float = 0.5, gap_s: float = 0.5,
                tail_s: float = 1.0) -> dict[str, Any]:
    """Write the playback sheet of ``split`` of a built dataset into ``out``; returns the
    manifest (also ``out/manifest.json``). Each talker's file is its dry stem
    (``source<k>_dry``: a dataset built with ``mixture.targets: [dry]``). The chirp
    defaults to :class:`Chirp` with its top at most 0.4 times the lowest sample rate (6 kHz
    from 16 kHz up, 3.2 kHz at 8 kHz)."""
    folder = DatasetFolder(dataset)
    out = Path(out)
    groups = folder.groups(split)
    if not groups:
        raise DatasetError(f"{folder.root}: split {split!r} has no groups")
    if chirp is None:
        lowest = min(g.sample_rate_hz for g in groups)
        chirp = Chirp(f_stop_hz=min(Chirp.f_stop_hz, 0.4 * lowest))
    takes, rows = [], []
    for group in groups:
        rate = group.sample_rate_hz
        dry = [group.read(f"{s}_dry") for s in group.speakers]
        if not dry:
            raise DatasetError(f"{folder.root / group.id}: no talkers (source1…) to play")
        # One channel per loudspeaker: a multichannel dry stem plays its first channel.
        dry = [d[0].astype(np.float64) for d in dry]
        n = max(len(d) for d in dry)
        peak = max(float(np.max(np.abs(d))) if d.size else 0.0 for d in dry)
        if peak == 0.0:
            raise DatasetError(f"{folder.root / group.id}: the dry talkers are silent")
        gain = 10 ** (PEAK_DBFS / 20) / peak
        sweep = chirp.samples(rate)
        take = Take(round(lead_s * rate), len(sweep), round(gap_s * rate), n,
                    round(tail_s * rate))
        files = []
        for k, (name, d) in enumerate(zip(group.speakers, dry, strict=True), start=1):
            x = np.zeros(take.length)
            x[take.content_start:take.content_start + len(d)] = gain * d
            if k == 1:
                x[take.start_chirp:take.start_chirp + take.chirp] += sweep
                x[take.end_chirp:take.end_chirp + take.chirp] += sweep
            rel = f"{group.id}/loudspeaker{k}.wav"
            _write_wav(out / rel, x[None], rate)
            ref = np.zeros(n)
            ref[:len(d)] = gain * d
            _write_wav(out / group.id / f"s{k}.wav", ref[None], rate, subtype="FLOAT")
            files.append({"loudspeaker": k, "talker": name, "file": rel,
                          "reference": f"{group.id}/s{k}.wav",
                          "position_m": _first_position(group, name)})
            rows.append({"take": group.id, "loudspeaker": k, "file": rel,
                         "start_s": 0.0, "talker_start_s": take.content_start / rate,
                         "talker_stop_s": (take.content_start + n) / rate,
                         "take_length_s": take.length / rate,
                         "sync": "yes" if k == 1 else "no"})
        takes.append({"group": group.id, "split": split, "item": group.id.split("/", 1)[1],
                      "sample_rate_hz": rate, "gain": gain, "layout_samples": asdict(take),
                      "recording": f"{group.id}.wav", "loudspeakers": files,
                      "microphone_position_m": _first_position(group, "microphone")})
    manifest = {"sheet_version": SHEET_VERSION, "dataset": str(folder.root.resolve()),
                "split": split, "chirp": asdict(chirp), "sync_loudspeaker": 1,
                "peak_dbfs": PEAK_DBFS, "takes": takes}
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text(out / "schedule.csv", buf.getvalue())
    write_text(out / "manifest.json", json.dumps(manifest, indent=2) + "\n")
    return manifest


def read_sheet(sheet: str | Path) -> dict[str, Any]:
    path = Path(sheet) / "manifest.json"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{path}: missing; --sheet is the folder `sonicspec playback` "
                           "wrote") from None
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: not JSON ({exc})") from None
    if manifest.get("sheet_version") != SHEET_VERSION:
        raise DatasetError(f"{path}: sheet_version {manifest.get('sheet_version')!r}; this "
                           f"sonicspec reads {SHEET_VERSION}")
    return manifest


# --- finding the chirps -------------------------------------------------------------------

def matched_filter(x: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cross-correlation ``r[i] = sum_j x[i+j] ref[j]`` and its normalised form
    ``r[i] / (|ref| |x[i:i+len(ref)]|)`` (the cosine between the chirp and the recording
    there; 1 for the chirp itself), for every ``i`` with the whole chirp inside ``x``."""
    from scipy.signal import fftconvolve

    m = len(ref)
    r = fftconvolve(x, ref[::-1], mode="valid")
    energy = np.concatenate(([0.0], np.cumsum(x * x)))
    local = np.sqrt(np.maximum(energy[m:] - energy[:-m], 0.0))
    norm = np.linalg.norm(ref) * local
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(norm > 0, r / np.where(norm > 0, norm, 1.0), 0.0)
    return r, rho


def whitened(sweep: np.ndarray, rate: float, chirp: Chirp | None = None) -> np.ndarray:
    """The sweep weighted by its instantaneous frequency over the start frequency,
    ``exp(t / L)`` with ``L = T / ln(f1 / f0)`` (Farina's inverse-filter weighting, reversed):
    correlating with it gives a flat spectrum over the sweep's band (the plain matched
    filter's falls 3 dB per octave, and its broad low-frequency peak blurs the direct sound
    into the first reflections)."""
    c = chirp or Chirp()
    t = np.arange(len(sweep)) / rate
    rate_l = c.duration_s / math.log(c.f_stop_hz / c.f_start_hz)
    w = np.exp(t / rate_l)
    return sweep * w / np.linalg.norm(sweep * w)


def refine_peak(r: np.ndarray, i: int, rate: float, half: int = 64) -> float:
    """The first arrival of the chirp near the correlation's maximum ``i``, to a fraction of a
    sample: on the Hilbert envelope of ``r`` from :data:`FIRST_ARRIVAL_S` before ``i``, the
    first local maximum that reaches half the largest (a strong reflection can top the direct
    sound; the direct sound comes first), refined by a parabola through its three samples."""
    from scipy.signal import hilbert

    lo = max(0, i - int(FIRST_ARRIVAL_S * rate) - half)
    hi = min(len(r), i + half + 1)
    env = np.abs(hilbert(r[lo:hi]))
    top = float(env[min(i - lo, len(env) - 1)])
    k = int(np.argmax(env >= 0.5 * max(top, float(env.max()) * 0.5)))
    while k + 1 < len(env) and env[k + 1] >= env[k]:
        k += 1
    if 0 < k < len(env) - 1:
        a, b, c = env[k - 1], env[k], env[k + 1]
        den = a - 2 * b + c
        frac = 0.5 * (a - c) / den if den != 0 else 0.0
    else:
        frac = 0.0
    return lo + k + float(np.clip(frac, -0.5, 0.5))


def find_chirps(x: np.ndarray, sweep: np.ndarray, spacing: int, rate: float, where: str,
                chirp: Chirp | None = None) -> tuple[float, float, float]:
    """The start and end chirps' arrivals in ``x`` (recorder samples, sub-sample) and the
    weaker of their normalised correlations. ``spacing`` is their distance in playback samples;
    the second is searched within :data:`MAX_DRIFT_PPM` of it."""
    if len(x) < len(sweep):
        raise DatasetError(f"{where}: {len(x)} samples, shorter than the sync chirp "
                           f"({len(sweep)}); the recording is cut short")
    from scipy.signal import fftconvolve

    _, rho = matched_filter(x, sweep)
    # Timing on the whitened correlation (the room's impulse response, band-limited to the
    # sweep: a sharp direct-sound peak); the normalised one scores it.
    r = fftconvolve(x, whitened(sweep, rate, chirp)[::-1], mode="valid")
    mag = np.abs(r)
    first = int(np.argmax(mag))
    best = float(abs(rho[first]))  # a loudspeaker wired in reverse polarity still counts
    if best < MIN_CORRELATION:
        raise DatasetError(f"{where}: sync chirp not found: the best normalised correlation "
                           f"with it is {best:.3f} (at {first} samples; at least "
                           f"{MIN_CORRELATION} expected); was loudspeaker 1 (the sync "
                           "loudspeaker) audible and the recording started before the take?")
    slack = math.ceil(spacing * MAX_DRIFT_PPM * 1e-6) + 2
    candidates = []
    for sign in (1, -1):
        centre = first + sign * spacing
        lo, hi = max(0, centre - slack), min(len(rho), centre + slack + 1)
        if lo < hi:
            j = lo + int(np.argmax(mag[lo:hi]))
            if lo < j < hi - 1 or lo == 0 or hi == len(rho):  # a peak, not a slope's edge
                candidates.append((float(abs(rho[j])), j))
    other = max(candidates, default=None)
    if other is None or other[0] < MIN_CORRELATION:
        seen = f"{other[0]:.3f} at {other[1]} samples" if other else "none (outside the file)"
        # Is the other chirp there, only farther than a plausible drift?
        far = [j for j in np.argsort(mag)[::-1][:50]
               if abs(abs(int(j) - first) - spacing) > slack and abs(int(j) - first) > len(sweep)
               and abs(rho[j]) >= MIN_CORRELATION]
        if far:
            ppm = (abs(int(far[0]) - first) / spacing - 1) * 1e6
            raise DatasetError(f"{where}: the chirps are {abs(int(far[0]) - first)} samples "
                               f"apart, the sheet plays them {spacing} apart: a clock drift "
                               f"of {ppm:+.0f} ppm, beyond the plausible ±{MAX_DRIFT_PPM:.0f}"
                               " ppm (a wrong sample rate, or a take recorded from another "
                               "sheet?)")
        raise DatasetError(f"{where}: the second sync chirp not found within "
                           f"±{MAX_DRIFT_PPM:.0f} ppm of {spacing} samples from the one at "
                           f"{first} samples: the best normalised correlation there is {seen} "
                           f"(at least {MIN_CORRELATION} expected); the recording stops early "
                           "or started late")
    a, b = sorted((first, other[1]))
    return refine_peak(r, a, rate), refine_peak(r, b, rate), min(best, other[0])


# --- resampling onto the playback clock -----------------------------------------------------

def resample_at(x: np.ndarray, start: float, ratio: float, n: int,
                half: int = SINC_HALF_TAPS) -> np.ndarray:
    """``y[m] = x(start + m * ratio)`` for ``m < n``: band-limited (windowed-sinc, Kaiser
    beta 8.6, ``2 * half`` taps) interpolation of ``x`` (channels, samples) at fractional
    positions. With ``ratio > 1`` (a recorder running fast) the kernel is widened by
    ``ratio`` so the result stays below its Nyquist frequency. Samples outside ``x`` are 0."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    cutoff = min(1.0, 1.0 / ratio) * 0.97
    out = np.zeros((x.shape[0], n))
    pad = half + 2
    xp = np.pad(x, ((0, 0), (pad, pad)))
    taps = np.arange(-half + 1, half + 1)
    # The kernel at PHASES fractional offsets (and 1), linearly interpolated between them
    # (an error below 1e-6 of full scale): evaluating the Kaiser window's Bessel function per
    # output sample and tap costs ten times the rest.
    d = np.arange(PHASES + 1)[:, None] / PHASES - taps[None, :]
    beta = 8.6  # the Kaiser window's shape (about -90 dB side lobes)
    win = np.i0(beta * np.sqrt(np.clip(1.0 - (d / half) ** 2, 0.0, None))) / np.i0(beta)
    table = cutoff * np.sinc(cutoff * d) * win * (np.abs(d) <= half)
    block = 8192
    for s in range(0, n, block):
        m = np.arange(s, min(n, s + block))
        t = start + m * ratio
        base = np.floor(t).astype(np.int64)
        phase = (t - base) * PHASES
        i = np.minimum(phase.astype(np.int64), PHASES - 1)
        a = (phase - i)[:, None]
        kern = table[i] * (1.0 - a) + table[i + 1] * a
        idx = base[:, None] + taps[None, :]
        ok = (idx + pad >= 0) & (idx + pad < xp.shape[1])
        gathered = xp[:, np.clip(idx + pad, 0, xp.shape[1] - 1)] * ok
        out[:, m] = np.einsum("cmk,mk->cm", gathered, kern)
    return out


@dataclass(frozen=True)
class Alignment:
    """Where one take sits in its recording: the start chirp's arrival (recorder samples),
    the recorder's samples per played sample (``ratio``), the drift in ppm and the weaker
    chirp's normalised correlation."""

    group: str
    recording: str
    start_chirp: float
    end_chirp: float
    ratio: float
    drift_ppm: float
    correlation: float


def align_take(x: np.ndarray, rate: int, take: dict[str, Any], chirp: Chirp,
               where: str) -> tuple[Alignment, np.ndarray]:
    """Align one recording (channels, samples) to its take; returns the alignment and the
    talkers' span on the playback clock, ``(channels, content)`` samples."""
    lay = Take(**take["layout_samples"])
    if rate != take["sample_rate_hz"]:
        raise DatasetError(f"{where}: recorded at {rate} Hz, the sheet plays at "
                           f"{take['sample_rate_hz']} Hz; record at the sheet's rate")
    spacing = lay.end_chirp - lay.start_chirp
    shortest = int((spacing + lay.chirp) * (1 - MAX_DRIFT_PPM * 1e-6))
    if x.shape[1] < shortest:
        raise DatasetError(f"{where}: {x.shape[1]} samples ({x.shape[1] / rate:.3f} s), "
                           f"shorter than the schedule: the take plays {spacing + lay.chirp} "
                           f"samples ({(spacing + lay.chirp) / rate:.3f} s) from its first "
                           "chirp to the end of its last; record the whole take")
    mono = x.sum(axis=0)
    t0, t1, corr = find_chirps(mono, chirp.samples(rate), spacing, rate, where, chirp)
    ratio = (t1 - t0) / spacing
    if abs(ratio - 1.0) <= MAX_DRIFT_PPM * 1e-6:
        # Again with the sweep as the drifting recorder hears it (sampled at rate * ratio):
        # the played sweep's correlation peak moves with the drift (by about 0.8 samples for
        # 50 ppm over a 1 s sweep at 16 kHz), the same for both chirps, so the ratio holds but
        # the offset does not.
        heard = rate * ratio
        t0, t1, corr = find_chirps(mono, chirp.samples(heard), round(spacing * ratio),
                                   heard, where, chirp)
        ratio = (t1 - t0) / spacing
    ppm = (ratio - 1.0) * 1e6
    if abs(ppm) > MAX_DRIFT_PPM:
        raise DatasetError(f"{where}: a clock drift of {ppm:+.1f} ppm from the chirps "
                           f"({t1 - t0:.2f} samples apart, {spacing} played), beyond the "
                           f"plausible ±{MAX_DRIFT_PPM:.0f} ppm")
    start = t0 + (lay.content_start - lay.start_chirp) * ratio
    need = start + lay.content * ratio + SINC_HALF_TAPS
    if need > x.shape[1]:
        raise DatasetError(f"{where}: {x.shape[1]} samples ({x.shape[1] / rate:.3f} s), the "
                           f"take's talkers end at sample {math.ceil(need)} "
                           f"({need / rate:.3f} s): the recording is shorter than the "
                           "schedule")
    cut = resample_at(x, start, ratio, lay.content)
    return Alignment(take["group"], where, t0, t1, ratio, ppm, corr), cut


def align(recordings: str | Path, sheet: str | Path, out: str | Path) -> list[Alignment]:
    """Align every take's recording ``<recordings>/<group>.wav`` and write the ``plain``
    layout into ``out``: ``<split>/<item>/mixture.wav`` (float WAV, all recorded channels)
    and ``s<k>.wav`` (the references from the sheet), plus ``alignment.json``."""
    recordings, sheet, out = Path(recordings), Path(sheet), Path(out)
    manifest = read_sheet(sheet)
    if not recordings.is_dir():
        raise DatasetError(f"{recordings}: no such folder (expected <group>.wav per take)")
    chirp = Chirp(**manifest["chirp"])
    done = []
    missing = [t["recording"] for t in manifest["takes"]
               if not (recordings / t["recording"]).is_file()]
    if missing:
        raise DatasetError(f"{recordings}: no recording of {len(missing)} take(s), first "
                           f"{missing[0]}; record each take to <recordings>/<group>.wav")
    for take in manifest["takes"]:
        path = recordings / take["recording"]
        x, rate = _read_wav(path)
        result, cut = align_take(x, rate, take, chirp, str(path))
        item = out / take["split"] / take["item"]
        _write_wav(item / "mixture.wav", cut, rate, subtype="FLOAT")
        for ls in take["loudspeakers"]:
            ref, _ = _read_wav(sheet / ls["reference"])
            _write_wav(item / f"s{ls['loudspeaker']}.wav", ref, rate, subtype="FLOAT")
        done.append(result)
    write_text(out / "alignment.json",
               json.dumps({"sheet": str(sheet.resolve()), "recordings": str(recordings),
                           "takes": [asdict(a) for a in done]}, indent=2) + "\n")
    return done
