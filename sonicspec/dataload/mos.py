"""Non-intrusive MOS estimates with model files the user holds: DNSMOS P.835 and P.808.

Nothing is downloaded: ``sonicspec evaluate --dnsmos-dir DIR`` names a folder holding
Microsoft's ONNX files as the DNS Challenge repository ships them (``DNSMOS/DNSMOS/``:
``sig_bak_ovr.onnx`` for P.835, and ``DNSMOS/model_v8.onnx`` for P.808, copied beside it),
or ``speechmos``: the files the ``speechmos`` package ships (MIT licence, Microsoft's AEC
Challenge organisers; ``speechmos/dnsmos_models/`` holds both, found without importing the
package). Each kind of MOS model is an entry of :data:`MOS_MODELS`: its files and their
checks, and how it scores a clip; a new kind (NISQA, SigMOS) is one more entry.

DNSMOS, as Microsoft's reference (``DNSMOS/dnsmos_local.py`` in microsoft/DNS-Challenge)
computes it, re-implemented here: the clip at 16 kHz (resampled by a polyphase filter where
the reference uses librosa's resampler), repeated end to end until it is at least 9.01 s long;
9.01 s segments (144,160 samples) every 1 s, less those the reference skips (its floating-point
cut leaves them one sample short: :func:`segments`); each segment through the P.835 model (raw
signal, background and overall ratings), mapped by the reference's polynomials (its
non-personalised ones), and its first 9.00 s through the P.808 model as a 120-band log mel
spectrogram; each rating is the mean over the segments.
"""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.dataload.folder import DatasetError
from sonicspec.hashing import file_sha256

RATE_HZ = 16000
SEGMENT = 144160  # 9.01 s at 16 kHz: the models' input
HOP = RATE_HZ  # a segment every second
P808_DROP = 160  # the P.808 model reads the segment's first 9.00 s: 900 frames of 10 ms
N_FFT = 321
MEL_HOP = 160
N_MELS = 120
TOP_DB = 80.0
# The reference's fits from the P.835 model's raw outputs to the ratings (highest power first).
P835_POLY = {"sig": (-0.08397278, 1.22083953, 0.0052439),
             "bak": (-0.13166888, 1.60915514, -0.39604546),
             "ovrl": (-0.06766283, 1.11546468, 0.04602535)}
_INSTALL = "pip install 'sonicspec[mos]'"


def file_record(path: Path) -> dict[str, Any]:
    """A model file as the summary states it: path, size and SHA-256."""
    return {"path": str(path.resolve()), "bytes": path.stat().st_size,
            "sha256": file_sha256(path)}


def _onnxruntime():
    try:
        import onnxruntime
    except ImportError:
        raise DatasetError(f"the onnxruntime package is needed for MOS metrics; {_INSTALL}"
                           ) from None
    return onnxruntime


def _session(path: Path, expect_inputs: tuple[tuple[Any, ...], ...], what: str):
    """An onnxruntime session for ``path`` whose input shape matches one of ``expect_inputs``
    (``None`` for any size along an axis); :class:`DatasetError` naming the file otherwise."""
    ort = _onnxruntime()
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    try:
        sess = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own (Fail, InvalidProtobuf...) classes
        raise DatasetError(f"{path}: not a loadable ONNX model ({what}): "
                           f"{str(exc).splitlines()[0][:200]}") from None
    inputs = sess.get_inputs()
    shape = tuple(inputs[0].shape) if len(inputs) == 1 else None

    def fits(want: tuple[Any, ...]) -> bool:
        return shape is not None and len(shape) == len(want) and all(
            w is None or not isinstance(s, int) or s == w for s, w in zip(shape, want,
                                                                           strict=True))

    if not any(fits(w) for w in expect_inputs):
        got = [tuple(i.shape) for i in inputs]
        raise DatasetError(f"{path}: expected the {what} (one input of shape "
                           f"{' or '.join(str(list(w)) for w in expect_inputs)}), got inputs "
                           f"{got}")
    return sess


def _hz_to_mel(f: np.ndarray) -> np.ndarray:
    """Slaney's mel scale: linear below 1 kHz (200/3 Hz per mel), logarithmic above."""
    f = np.asarray(f, dtype=np.float64)
    lin = f / (200.0 / 3.0)
    logstep = math.log(6.4) / 27.0
    return np.where(f >= 1000.0, 15.0 + np.log(np.maximum(f, 1e-12) / 1000.0) / logstep, lin)


def _mel_to_hz(m: np.ndarray) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    logstep = math.log(6.4) / 27.0
    return np.where(m >= 15.0, 1000.0 * np.exp(logstep * (m - 15.0)), m * (200.0 / 3.0))


def mel_filters(rate: int = RATE_HZ, n_fft: int = N_FFT, n_mels: int = N_MELS) -> np.ndarray:
    """``(n_mels, n_fft // 2 + 1)`` triangular filters on Slaney's scale from 0 Hz to
    Nyquist, each scaled to unit area (Slaney's normalisation): the filter bank
    ``librosa.filters.mel`` makes by default."""
    fft_hz = np.fft.rfftfreq(n_fft, 1.0 / rate)
    mel_hz = _mel_to_hz(np.linspace(_hz_to_mel(0.0), _hz_to_mel(rate / 2.0), n_mels + 2))
    width = np.diff(mel_hz)
    ramps = mel_hz[:, None] - fft_hz[None, :]
    lower = -ramps[:-2] / width[:-1, None]
    upper = ramps[2:] / width[1:, None]
    weights = np.maximum(0.0, np.minimum(lower, upper))
    return weights * (2.0 / (mel_hz[2:] - mel_hz[:-2]))[:, None]


def log_mel(audio: np.ndarray) -> np.ndarray:
    """The P.808 model's input, ``(frames, 120)``: the power spectrogram (periodic Hann window
    of 321 samples, every 160, frames centred on reflection-padded ends), on 120 mel bands, in
    dB below its maximum (floored 80 dB down), mapped by ``(dB + 40) / 40``."""
    x = np.asarray(audio, dtype=np.float64)
    pad = N_FFT // 2
    x = np.pad(x, pad, mode="reflect")
    frames = 1 + (len(x) - N_FFT) // MEL_HOP
    idx = np.arange(N_FFT)[None, :] + MEL_HOP * np.arange(frames)[:, None]
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(N_FFT) / N_FFT)
    power = np.abs(np.fft.rfft(x[idx] * window, axis=1)) ** 2
    mel = power @ mel_filters().T
    db = 10.0 * np.log10(np.maximum(mel, 1e-10))
    db -= 10.0 * np.log10(max(float(mel.max()), 1e-10))
    db = np.maximum(db, db.max() - TOP_DB)
    return (db + 40.0) / 40.0


def segments(audio: np.ndarray) -> list[np.ndarray]:
    """The 9.01 s segments a clip at 16 kHz is rated on: the clip repeated end to end until it
    is at least 9.01 s, then a segment every second that fits whole, as the reference picks
    them. The reference cuts segment ``i`` at ``int((i + 9.01) * 16000)`` in floating point,
    which falls one sample short for ``i`` = 7…23, 119…122 (and more further on), and skips
    those segments as too short; they are skipped here too, so that the ratings are the
    reference's (a clip of 30 s is rated on its segments at 0…6 s)."""
    x = np.asarray(audio, dtype=np.float32)
    if len(x) == 0:
        raise DatasetError("DNSMOS: expected a clip with samples, got an empty one")
    while len(x) < SEGMENT:
        x = np.concatenate([x, x])
    hops = int(len(x) // RATE_HZ - SEGMENT / RATE_HZ) + 1
    out = []
    for i in range(hops):
        start = i * HOP
        stop = int((i + SEGMENT / RATE_HZ) * RATE_HZ)  # the reference's arithmetic
        if stop - start >= SEGMENT and start + SEGMENT <= len(x):
            out.append(x[start:start + SEGMENT])
    return out


@dataclass
class Dnsmos:
    """DNSMOS from a folder holding ``sig_bak_ovr.onnx`` (P.835) and ``model_v8.onnx``
    (P.808)."""

    folder: Path
    files: list[dict[str, Any]] = field(default_factory=list)

    FILES = ("sig_bak_ovr.onnx", "model_v8.onnx")
    COLUMNS = ("dnsmos_sig", "dnsmos_bak", "dnsmos_ovrl", "dnsmos_p808")

    def __post_init__(self) -> None:
        paths = check_files(self.folder, self.FILES, "DNSMOS", "--dnsmos-dir")
        self._p835 = _session(paths[0], ((None, SEGMENT),), "DNSMOS P.835 model "
                              "(sig_bak_ovr.onnx: a 9.01 s clip at 16 kHz in, SIG BAK OVRL out)")
        frames = 1 + (SEGMENT - P808_DROP + 2 * (N_FFT // 2) - N_FFT) // MEL_HOP  # 900
        self._p808 = _session(paths[1], ((None, frames, N_MELS),), "DNSMOS P.808 model "
                              "(model_v8.onnx: a 900 x 120 log mel spectrogram in)")
        self.files = [file_record(p) for p in paths]

    def __call__(self, audio: np.ndarray, rate: int) -> dict[str, float]:
        """The four ratings of a clip (any rate; one channel)."""
        x = np.asarray(audio, dtype=np.float64)
        if rate != RATE_HZ:
            from scipy.signal import resample_poly

            g = math.gcd(int(rate), RATE_HZ)
            x = resample_poly(x, RATE_HZ // g, int(rate) // g)
        p835 = self._p835.get_inputs()[0].name
        p808 = self._p808.get_inputs()[0].name
        raw, mos808 = [], []
        for seg in segments(x):
            out = np.asarray(self._p835.run(None, {p835: seg[None, :]})[0], np.float64)
            raw.append(out.reshape(-1)[:3])
            feats = log_mel(seg[:-P808_DROP]).astype(np.float32)[None]
            mos808.append(float(np.asarray(self._p808.run(None, {p808: feats})[0]
                                           ).reshape(-1)[0]))
        raws = np.asarray(raw)
        out = {f"dnsmos_{k}": float(np.mean(np.polyval(P835_POLY[k], raws[:, i])))
               for i, k in enumerate(("sig", "bak", "ovrl"))}
        out["dnsmos_p808"] = float(np.mean(mos808))
        return out


def check_files(folder: Path, names: tuple[str, ...], kind: str, option: str) -> list[Path]:
    """The model files of ``folder``, each checked to exist and be non-empty."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DatasetError(f"{option} {folder}: no such folder; expected a folder holding "
                           f"the {kind} model files {', '.join(names)}")
    missing = [n for n in names if not (folder / n).is_file()]
    if missing:
        raise DatasetError(f"{option} {folder}: missing {', '.join(missing)}; expected the "
                           f"{kind} model files {', '.join(names)} in it")
    empty = [n for n in names if (folder / n).stat().st_size == 0]
    if empty:
        raise DatasetError(f"{option} {folder}: {', '.join(empty)} is empty; expected the "
                           f"{kind} model file (a download cut short?)")
    return [folder / n for n in names]


def speechmos_dir() -> Path:
    """The ``dnsmos_models`` folder of the installed ``speechmos`` package (not imported)."""
    spec = importlib.util.find_spec("speechmos")
    if spec is None or not spec.submodule_search_locations:
        raise DatasetError("--dnsmos-dir speechmos: the speechmos package is not installed "
                           "(pip install speechmos: it ships Microsoft's DNSMOS ONNX files); "
                           "or give the folder holding sig_bak_ovr.onnx and model_v8.onnx")
    return Path(next(iter(spec.submodule_search_locations))) / "dnsmos_models"


@dataclass(frozen=True)
class MosKind:
    """One kind of MOS model: its files, the columns it adds, how to open it."""

    name: str
    files: tuple[str, ...]
    columns: tuple[str, ...]
    open: Callable[[Path], Any]
    packaged: Callable[[], Path] | None = None  # ``--<kind>-dir <package>``: its shipped files


MOS_MODELS: dict[str, MosKind] = {
    "dnsmos": MosKind("dnsmos", Dnsmos.FILES, Dnsmos.COLUMNS, Dnsmos, speechmos_dir),
}


def open_mos(kind: str, where: str | Path) -> Any:
    """The MOS model ``kind`` from a folder, or from the package that ships it
    (``speechmos`` for DNSMOS)."""
    if kind not in MOS_MODELS:
        raise DatasetError(f"MOS model: expected one of {list(MOS_MODELS)}, got {kind!r}")
    entry = MOS_MODELS[kind]
    folder = entry.packaged() if entry.packaged and str(where) == "speechmos" else Path(where)
    return entry.open(folder)
