"""Device and channel effects: what a recording device and a transmission channel do to a
mixture (issue 30).

A chain is a list of effects applied in order, each with a probability and parameter ranges
(the ``augmentation:`` block of a spec, or the loader's ``augmentation=`` argument, as plain
data: :func:`parse_chain` checks it). :func:`draw_chain` makes one concrete draw of it from a
generator the caller seeds (per group in a build, per item and epoch in the loader); the draw is
plain JSON (``metadata.json`` records it) and :func:`apply_chain` applies it, so the same draw
always gives the same bytes.

Effects (``kind``):

* ``response`` — a microphone's frequency response: a preset of :data:`RESPONSE_PRESETS` or
  the user's ``points`` ([Hz, dB] pairs, interpolated linearly in dB over log frequency, held
  flat beyond the ends), applied as a minimum-phase FIR (a capsule is a minimum-phase system:
  no bulk delay, so the mixture stays aligned with its targets).
* ``impulse_response`` — a measured device impulse response (the caller reads the files; the
  response is scaled to unit energy and advanced by its peak's index, so it colours without
  moving or re-levelling the signal).
* ``self_noise`` — white or pink noise at an SNR against the signal (mean power over the
  clip and the channels), independent per channel (each capsule's own noise).
* ``gain`` — a gain, dB; ``clipping`` — hard clipping at a level, dBFS.
* ``resample`` — down to a lower rate and back with :func:`sonicspec.audio.corpora.resample`
  (flat to 0.9 × the lower Nyquist frequency, about 90 dB down above it).
* ``mp3``, ``opus``, ``gsm`` — encoded and decoded by libsndfile (through ``soundfile``):
  MP3 constant bit rate (LAME), Opus (libopus; variable bit rate around the asked rate),
  GSM 06.10 full rate (13 kbit/s at 8 kHz, the narrow-band phone codec; the signal is resampled
  to 8 kHz and back). Each channel is coded alone (bit rates are per channel); libsndfile
  removes the codecs' delay and padding (where an MP3 lacks the tag that says how much, the
  delay is found by cross-correlation), so the decoded signal is sample-aligned.
* ``one_of`` — one of several effects, drawn with weights.

Every effect has ``probability`` (drawn once per draw) and ``targets`` (also applied to the
clean targets; default ``False``: the targets stay clean).
"""

from __future__ import annotations

import io
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonicspec.errors import AudioError

# ----------------------------------------------------------------------- response presets
# Each preset: [Hz, dB] points (linear in dB over log frequency, flat beyond the ends) and
# where its shape comes from. They are parametric shapes of a device class, not the
# measurement of one unit: use `impulse_response` with a measured response for a real device.
RESPONSE_PRESETS: dict[str, dict[str, Any]] = {
    "smartphone": {
        "points": [[50, -18.0], [100, -8.0], [200, -2.0], [400, 0.0], [2000, 0.0],
                   [4000, 1.5], [6000, 3.5], [8000, 5.0], [12000, 6.0], [16000, 2.0]],
        "source": "shape of a bottom-port MEMS capsule behind a phone's sound port: the "
        "capsule's vent roll-off plus a voice high-pass near 150 Hz, and the port's Helmholtz "
        "resonance lifting the top octave by a few dB (the rising top end of MEMS datasheet "
        "response curves, e.g. InvenSense AN-1112 'Microphone Specifications Explained'); "
        "parametric, not one unit's measurement",
    },
    "laptop": {
        "points": [[80, -20.0], [150, -10.0], [300, -3.0], [500, 0.0], [1500, 0.0],
                   [3000, 3.0], [5000, 1.0], [7000, -4.0], [10000, -12.0], [16000, -20.0]],
        "source": "shape of capsules in a laptop bezel: a strong voice high-pass near "
        "250 Hz (against fan and keyboard rumble), a cavity peak near 3 kHz and the top "
        "octave lost to the small port and the voice processing; parametric, not one unit's "
        "measurement",
    },
    "headset": {
        "points": [[50, -15.0], [100, -6.0], [200, -1.0], [400, 0.0], [1000, 0.0],
                   [2500, 3.0], [4000, 4.0], [6000, 1.0], [8000, -3.0], [12000, -10.0]],
        "source": "shape of a close-talking boom electret: a high-pass against proximity "
        "bass and breath, a presence rise of +3 to +4 dB at 2-5 kHz and a roll-off above "
        "7 kHz (the wideband 100 Hz-7 kHz band of ITU-T P.341's send mask); parametric, not "
        "one unit's measurement",
    },
    "telephone": {
        "points": [[100, -30.0], [200, -12.0], [300, -1.0], [400, 0.0], [3000, 0.0],
                   [3400, -1.0], [3700, -10.0], [4000, -30.0]],
        "source": "the narrow-band telephone channel: flat 300-3400 Hz (the pass band of "
        "ITU-T G.712's channel mask and of the IRS send masks of ITU-T P.48), steep skirts "
        "outside; parametric",
    },
}

MP3_BITRATES_KBPS = {  # allowed constant bit rates by MPEG version (ISO 11172-3 / 13818-3)
    "mpeg1": (32, 40, 48, 56, 64, 80, 96, 112, 128, 160, 192, 224, 256, 320),
    "mpeg2": (8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160),
}
MP3_RATES_HZ = (8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000)
OPUS_RATES_HZ = (8000, 12000, 16000, 24000, 48000)
OPUS_BITRATE_KBPS = (6.0, 256.0)  # per channel: libsndfile maps its level 0..1 onto this
GSM_RATE_HZ = 8000
GSM_BITRATE_KBPS = 13.0
KINDS = ("response", "impulse_response", "self_noise", "gain", "clipping", "resample",
         "mp3", "opus", "gsm", "one_of")
_COMMON = ("kind", "probability", "targets")


# --------------------------------------------------------------------------- the chain
@dataclass(frozen=True)
class Effect:
    """One checked effect of a chain: its kind, probability, targets flag and parameters
    (``one_of``: ``inner`` holds its effects and ``params["weights"]`` their weights)."""

    kind: str
    probability: float = 1.0
    targets: bool = False
    params: Mapping[str, Any] = field(default_factory=dict)
    inner: tuple[Effect, ...] = ()


def _fail(where: str, expected: str, got: Any) -> AudioError:
    return AudioError(f"{where}: expected {expected}, got {got!r}")


def _number(x: Any, where: str, lo: float | None = None, hi: float | None = None,
            *, integer: bool = False) -> float:
    ok_type = isinstance(x, int | float) and not isinstance(x, bool)
    if not ok_type or not math.isfinite(float(x)) or (integer and not float(x).is_integer()):
        raise _fail(where, "a whole number" if integer else "a finite number", x)
    v = float(x)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise _fail(where, f"a value in [{lo:g}, {hi:g}]" if lo is not None and hi is not None
                    else (f"a value >= {lo:g}" if lo is not None else f"a value <= {hi:g}"), x)
    return v


def _range(x: Any, where: str, lo: float, hi: float) -> tuple[float, float]:
    if not isinstance(x, list | tuple) or len(x) != 2:
        raise _fail(where, f"a range [min, max] with both ends in [{lo:g}, {hi:g}] ([x, x] "
                    "fixes the value)", x)
    a, b = (_number(v, where, lo, hi) for v in x)
    if a > b:
        raise _fail(where, "[min, max] with min <= max", list(x))
    return a, b


def _choices(x: Any, where: str, check: Callable[[Any, str], Any],
             what: str = "values") -> tuple[Any, ...]:
    if not isinstance(x, list | tuple) or not x:
        raise _fail(where, f"a non-empty list of {what}, one drawn per group", x)
    return tuple(check(v, f"{where}[{i}]") for i, v in enumerate(x))


def _preset(x: Any, where: str) -> str:
    if x not in RESPONSE_PRESETS:
        raise _fail(where, f"one of {sorted(RESPONSE_PRESETS)}", x)
    return str(x)


def _points(x: Any, where: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(x, list | tuple) or len(x) < 2:
        raise _fail(where, "at least two [Hz, dB] points", x)
    out = []
    for i, p in enumerate(x):
        if not isinstance(p, list | tuple) or len(p) != 2:
            raise _fail(f"{where}[{i}]", "[Hz, dB]", p)
        out.append((_number(p[0], f"{where}[{i}]", 1.0, 1e5), _number(p[1], f"{where}[{i}]",
                                                                      -60.0, 30.0)))
    if any(b[0] <= a[0] for a, b in itertools.pairwise(out)):
        raise _fail(where, "points in increasing frequency", list(x))
    return tuple(out)


def _parse_params(kind: str, d: Mapping[str, Any], where: str) -> dict[str, Any]:
    """The parameters of one effect of ``kind``, checked (names the field of a bad value)."""
    p: dict[str, Any] = {}
    allowed: tuple[str, ...]
    if kind == "response":
        allowed = ("preset", "points")
        has_preset, has_points = d.get("preset") is not None, d.get("points") is not None
        if has_preset == has_points:
            raise AudioError(f"{where}: expected either preset or points, got "
                             f"{'both' if has_preset else 'neither'}")
        if has_preset:
            p["preset"] = _choices(d["preset"], f"{where}.preset", _preset,
                                   f"presets ({', '.join(sorted(RESPONSE_PRESETS))})")
        else:
            p["points"] = _points(d["points"], f"{where}.points")
    elif kind == "impulse_response":
        allowed = ("files",)
        p["files"] = _choices(d.get("files"), f"{where}.files", _file_name,
                              "impulse-response files")
    elif kind == "self_noise":
        allowed = ("snr_db", "color")
        p["snr_db"] = _range(d.get("snr_db"), f"{where}.snr_db", -20.0, 100.0)
        color = d.get("color", "white")
        if color not in ("white", "pink"):
            raise _fail(f"{where}.color", "'white' or 'pink'", color)
        p["color"] = color
    elif kind == "gain":
        allowed = ("gain_db",)
        p["gain_db"] = _range(d.get("gain_db"), f"{where}.gain_db", -60.0, 40.0)
    elif kind == "clipping":
        allowed = ("threshold_dbfs",)
        p["threshold_dbfs"] = _range(d.get("threshold_dbfs"), f"{where}.threshold_dbfs",
                                     -60.0, 0.0)
    elif kind == "resample":
        allowed = ("rate_hz",)
        p["rate_hz"] = _choices(d.get("rate_hz"), f"{where}.rate_hz",
                                lambda v, w: int(_number(v, w, 1000, 192000, integer=True)),
                                "sample rates in Hz (1000-192000)")
    elif kind == "mp3":
        allowed = ("bitrate_kbps",)
        every = sorted(set(MP3_BITRATES_KBPS["mpeg1"]) | set(MP3_BITRATES_KBPS["mpeg2"]))

        def bitrate(v: Any, w: str) -> int:
            if isinstance(v, bool) or v not in every:
                raise _fail(w, f"an MP3 bit rate, kbit/s, one of {every}", v)
            return int(v)

        p["bitrate_kbps"] = _choices(d.get("bitrate_kbps"), f"{where}.bitrate_kbps", bitrate,
                                     "MP3 bit rates in kbit/s")
    elif kind == "opus":
        allowed = ("bitrate_kbps",)
        p["bitrate_kbps"] = _range(d.get("bitrate_kbps"), f"{where}.bitrate_kbps",
                                   *OPUS_BITRATE_KBPS)
    elif kind == "gsm":
        allowed = ()
    else:
        raise AssertionError(kind)
    extra = sorted(set(d) - set(allowed) - set(_COMMON))
    if extra:
        raise AudioError(f"{where}.{extra[0]}: not a field of a {kind!r} effect (fields: "
                         f"{', '.join([*_COMMON, *allowed])})")
    return p


def _file_name(x: Any, where: str) -> str:
    if not isinstance(x, str) or not x:
        raise _fail(where, "a file name", x)
    return x


def parse_effect(d: Any, where: str, *, nested: bool = False) -> Effect:
    """One effect of a chain from plain data (a spec's ``augmentation.effects[i]``)."""
    if not isinstance(d, Mapping):
        raise _fail(where, "a mapping with a kind", d)
    kind = d.get("kind")
    if kind not in KINDS or (nested and kind == "one_of"):
        allowed = [k for k in KINDS if not (nested and k == "one_of")]
        raise _fail(f"{where}.kind", f"one of {allowed}", kind)
    probability = _number(d.get("probability", 1.0), f"{where}.probability", 0.0, 1.0)
    targets = d.get("targets", False)
    if not isinstance(targets, bool):
        raise _fail(f"{where}.targets", "true or false", targets)
    if kind == "one_of":
        extra = sorted(set(d) - {*_COMMON, "effects", "weights"})
        if extra:
            raise AudioError(f"{where}.{extra[0]}: not a field of a 'one_of' effect (fields: "
                             f"{', '.join([*_COMMON, 'effects', 'weights'])})")
        effects = d.get("effects")
        if not isinstance(effects, list | tuple) or not effects:
            raise _fail(f"{where}.effects", "a non-empty list of effects", effects)
        inner = tuple(parse_effect(e, f"{where}.effects[{i}]", nested=True)
                      for i, e in enumerate(effects))
        weights = d.get("weights")
        if weights is None:
            weights = [1.0] * len(inner)
        w = _choices(weights, f"{where}.weights", lambda v, s: _number(v, s, 0.0, None),
                     "weights >= 0, one per effect")
        if len(w) != len(inner) or sum(w) <= 0:
            raise _fail(f"{where}.weights", f"{len(inner)} weights >= 0 with a positive sum",
                        list(weights))
        return Effect("one_of", probability, targets, {"weights": w}, inner)
    return Effect(kind, probability, targets, _parse_params(kind, d, where))


def parse_chain(data: Any, where: str = "augmentation") -> tuple[Effect, ...]:
    """A chain from plain data: a mapping ``{effects: [...]}`` (the spec block, or its
    ``model_dump()``), checked; an :class:`AudioError` names the field of a bad value."""
    if hasattr(data, "model_dump"):
        data = data.model_dump(mode="json")
    if not isinstance(data, Mapping):
        raise _fail(where, "a mapping with effects", data)
    extra = sorted(set(data) - {"effects"})
    if extra:
        raise AudioError(f"{where}.{extra[0]}: not a field of augmentation (fields: effects)")
    effects = data.get("effects")
    if not isinstance(effects, list | tuple):
        raise _fail(f"{where}.effects", "a list of effects", effects)
    return tuple(parse_effect(e, f"{where}.effects[{i}]") for i, e in enumerate(effects))


def chain_files(chain: Sequence[Effect]) -> list[str]:
    """Every impulse-response file a chain may draw, in order, once each."""
    out: list[str] = []
    for e in chain:
        for f in [*e.params.get("files", ()), *chain_files(e.inner)]:
            if f not in out:
                out.append(f)
    return out


# --------------------------------------------------------------------------- drawing
def _draw_params(e: Effect, rng: np.random.Generator) -> dict[str, Any]:
    p = e.params
    if e.kind == "response":
        if "preset" in p:
            return {"preset": p["preset"][int(rng.integers(len(p["preset"])))]}
        return {"points": [list(q) for q in p["points"]]}
    if e.kind == "impulse_response":
        return {"file": p["files"][int(rng.integers(len(p["files"])))]}
    if e.kind == "self_noise":
        return {"snr_db": float(rng.uniform(*p["snr_db"])), "color": p["color"],
                "seed": int(rng.integers(2**63 - 1))}
    if e.kind == "gain":
        return {"gain_db": float(rng.uniform(*p["gain_db"]))}
    if e.kind == "clipping":
        return {"threshold_dbfs": float(rng.uniform(*p["threshold_dbfs"]))}
    if e.kind == "resample":
        return {"rate_hz": int(p["rate_hz"][int(rng.integers(len(p["rate_hz"])))])}
    if e.kind == "mp3":
        return {"bitrate_kbps": int(p["bitrate_kbps"][int(rng.integers(len(p["bitrate_kbps"])))])}
    if e.kind == "opus":
        return {"bitrate_kbps": float(round(rng.uniform(*p["bitrate_kbps"])))}
    return {}  # gsm


def _draw_one(e: Effect, rng: np.random.Generator) -> dict[str, Any]:
    applied = bool(rng.random() < e.probability)
    out: dict[str, Any] = {"kind": e.kind, "applied": applied, "targets": e.targets}
    if e.kind == "one_of":
        w = np.asarray(e.params["weights"], dtype=np.float64)
        choice = int(rng.choice(len(e.inner), p=w / w.sum()))
        inner = _draw_one(e.inner[choice], rng)
        inner["applied"] = True  # its probability is the one_of's
        out.update(choice=choice, effect=inner)
    else:
        out.update(_draw_params(e, rng))
    return out


def draw_chain(chain: Sequence[Effect], rng: np.random.Generator) -> list[dict[str, Any]]:
    """One draw of every effect of ``chain``, in order (plain JSON): ``kind``, ``applied``
    (drawn with its probability), ``targets`` and the drawn parameters. Every effect is
    drawn whether applied or not, so one effect's probability never shifts another's draw."""
    return [_draw_one(e, rng) for e in chain]


# --------------------------------------------------------------------------- effects
def response_db(points: Sequence[Sequence[float]], freqs_hz: np.ndarray) -> np.ndarray:
    """The response of ``points`` at ``freqs_hz``, dB: linear in dB over log frequency
    between the points, flat beyond the ends."""
    pts = np.asarray(points, dtype=np.float64)
    f = np.clip(np.asarray(freqs_hz, dtype=np.float64), pts[0, 0], pts[-1, 0])
    return np.interp(np.log(f), np.log(pts[:, 0]), pts[:, 1])


def minimum_phase_fir(points: Sequence[Sequence[float]], rate_hz: int,
                      taps: int | None = None) -> np.ndarray:
    """A minimum-phase FIR whose magnitude follows ``points`` (homomorphic: the folded real
    cepstrum of the log magnitude on a fine grid), ``taps`` long (default: 128 ms)."""
    taps = taps or 1 << math.ceil(math.log2(0.128 * rate_hz))
    n = 8 * taps
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    log_mag = response_db(points, np.maximum(freqs, 1.0)) * (math.log(10.0) / 20.0)
    cep = np.fft.irfft(log_mag, n)
    fold = np.zeros(n)
    fold[0], fold[n // 2] = cep[0], cep[n // 2]
    fold[1:n // 2] = 2.0 * cep[1:n // 2]
    h = np.fft.irfft(np.exp(np.fft.rfft(fold)), n)[:taps]
    fade = max(1, taps // 8)  # the tail is ~0 for a smooth response; a half-Hann end on it
    h[-fade:] *= 0.5 * (1.0 + np.cos(np.linspace(0.0, math.pi, fade)))
    return h


def _filter(x: np.ndarray, h: np.ndarray, advance: int = 0) -> np.ndarray:
    from scipy.signal import oaconvolve  # overlap-add: a long signal, a short filter

    y = oaconvolve(x, h[None, :], axes=-1)
    return y[:, advance:advance + x.shape[-1]]


def _noise(shape: tuple[int, int], color: str, seed: int) -> np.ndarray:
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed])))
    w = rng.standard_normal(shape)
    if color == "pink":  # 1/f power: the spectrum scaled by 1/sqrt(f) (DC left out)
        spec = np.fft.rfft(w, axis=-1)
        f = np.arange(spec.shape[-1], dtype=np.float64)
        f[0] = 1.0
        spec /= np.sqrt(f)
        spec[:, 0] = 0.0
        w = np.fft.irfft(spec, shape[-1], axis=-1)
    return w / np.sqrt(np.mean(np.square(w)))


def _mp3_level(bitrate_kbps: float, rate_hz: int) -> float:
    """libsndfile's compression level for a constant MP3 bit rate: the inverse of its
    ``mpeg_l3_encoder_set_quality`` (bit rate = max − level × (max − min), truncated)."""
    lo, hi = (32.0, 320.0) if rate_hz >= 32000 else ((8.0, 160.0) if rate_hz >= 16000
                                                      else (8.0, 64.0))
    return min(1.0, max(0.0, (hi - bitrate_kbps - 0.5) / (hi - lo)))


def _opus_level(bitrate_kbps: float) -> float:
    """libsndfile's compression level for an Opus bit rate per channel (its level maps
    linearly from 256 kbit/s at 0 to 6 kbit/s at 1)."""
    lo, hi = OPUS_BITRATE_KBPS
    return min(1.0, max(0.0, (hi - bitrate_kbps) / (hi - lo)))


def _soundfile_codecs() -> Any:
    import soundfile

    formats = soundfile.available_formats()
    if "MP3" not in formats or "OPUS" not in soundfile.available_subtypes("OGG"):
        raise AudioError("augmentation codecs need libsndfile >= 1.1 with MP3 and Opus (this "
                         f"one is {soundfile.__libsndfile_version__}): pip install "
                         "'sonicspec[augment]' (soundfile >= 0.13 bundles it)")
    return soundfile


def _codec_rate(rate_hz: int, allowed: Sequence[int]) -> int:
    higher = [r for r in allowed if r >= rate_hz]
    return min(higher) if higher else max(allowed)


def _delay(x: np.ndarray, y: np.ndarray, most: int) -> int:
    """The lag in ``[0, most]`` at which ``y`` best matches ``x`` (cross-correlation)."""
    from scipy.signal import correlate

    n = x.size
    c = correlate(y[:n + most], x, mode="full", method="fft")[n - 1:n + most]
    return int(np.argmax(c)) if np.any(c) else 0


def encode_decode(x: np.ndarray, rate_hz: int, codec: str,
                  bitrate_kbps: float | None = None) -> tuple[np.ndarray, dict[str, float]]:
    """``x`` ``(C, T)`` coded and decoded by ``codec`` (``mp3``, ``opus``, ``gsm``), each
    channel alone; (the decoded signal at ``rate_hz``, ``T`` samples; the measured bit rate per
    channel, kbit/s: encoded bytes × 8 / duration, and the codec's own rate, Hz).

    At a rate the codec does not take the signal is resampled to the next it takes (GSM:
    8 kHz) and back.
    """
    from sonicspec.audio.corpora import resample

    sf = _soundfile_codecs()
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    allowed = {"mp3": MP3_RATES_HZ, "opus": OPUS_RATES_HZ, "gsm": (GSM_RATE_HZ,)}[codec]
    rate = GSM_RATE_HZ if codec == "gsm" else _codec_rate(rate_hz, allowed)
    z = resample(x, rate_hz, rate) if rate != rate_hz else x
    if codec == "mp3":
        table = MP3_BITRATES_KBPS["mpeg1" if rate >= 32000 else "mpeg2"]
        allowed_kbps = [b for b in table if rate >= 16000 or b <= 64]
        if bitrate_kbps not in allowed_kbps:
            raise AudioError(f"mp3 bitrate_kbps: {bitrate_kbps!r} kbit/s is not an MP3 bit "
                             f"rate at {rate} Hz (allowed: {allowed_kbps})")
    total_bytes, out = 0, []
    # The codecs take [-1, 1]: louder samples would clip in the encoder's input.
    for ch in np.clip(z, -1.0, 1.0):
        buf = io.BytesIO()
        if codec == "mp3":
            sf.write(buf, ch, rate, format="MP3", bitrate_mode="CONSTANT",
                     compression_level=_mp3_level(float(bitrate_kbps or 0), rate))
        elif codec == "opus":
            sf.write(buf, ch, rate, format="OGG", subtype="OPUS",
                     compression_level=_opus_level(float(bitrate_kbps or 0)))
        else:
            sf.write(buf, ch, rate, format="WAV", subtype="GSM610")
        data = buf.getvalue()
        total_bytes += len(data)
        y, _ = sf.read(io.BytesIO(data), dtype="float64", always_2d=False)
        y = np.asarray(y)
        if y.size > ch.size:
            # Delay and padding left in (an MP3 frame too short for LAME's gapless tag, as at
            # 32 kbit/s and 16 kHz): the delay is found where the decoded signal best matches.
            y = y[_delay(ch, y, y.size - ch.size):]
        y = y[:ch.size]
        out.append(np.pad(y, (0, ch.size - y.size)))
    decoded = np.stack(out)
    if rate != rate_hz:
        decoded = resample(decoded, rate, rate_hz)
    decoded = decoded[:, :x.shape[1]]
    if decoded.shape[1] < x.shape[1]:
        decoded = np.pad(decoded, ((0, 0), (0, x.shape[1] - decoded.shape[1])))
    seconds = z.shape[1] / rate
    return decoded, {"bitrate_kbps": total_bytes * 8.0 / seconds / 1000.0 / x.shape[0],
                     "codec_rate_hz": float(rate)}


def read_impulse_response(path: str | Path, rate_hz: int, *, where: str = "impulse_response"
                          ) -> np.ndarray:
    """A device impulse response from a sound file (its first channel) at ``rate_hz``."""
    import soundfile

    from sonicspec.audio.corpora import resample

    try:
        data, file_rate = soundfile.read(str(path), dtype="float64", always_2d=True)
    except (RuntimeError, soundfile.LibsndfileError) as err:
        raise AudioError(f"{where}: cannot read {path}: {err}") from None
    h = data[:, 0]
    if not np.all(np.isfinite(h)) or not np.any(h):
        raise AudioError(f"{where}: expected a finite, non-silent response in {path}, got "
                         "silence or NaN")
    return resample(h, file_rate, rate_hz) if file_rate != rate_hz else h


def _mean_power(x: np.ndarray) -> float:
    return float(np.mean(np.square(x)))


def _apply_one(d: Mapping[str, Any], x: np.ndarray, rate_hz: int,
               impulse_responses: Mapping[str, np.ndarray]) -> tuple[np.ndarray, dict[str, Any]]:
    kind = d["kind"]
    if kind == "one_of":
        return _apply_one(d["effect"], x, rate_hz, impulse_responses)
    if kind == "response":
        points = d["points"] if "points" in d else RESPONSE_PRESETS[d["preset"]]["points"]
        return _filter(x, minimum_phase_fir(points, rate_hz)), {}
    if kind == "impulse_response":
        if d["file"] not in impulse_responses:
            raise AudioError(f"augmentation impulse_response: {d['file']!r} was not read "
                             "(the caller passes every file of the chain)")
        h = np.asarray(impulse_responses[d["file"]], dtype=np.float64)
        h = h / math.sqrt(float(np.sum(np.square(h))))
        return _filter(x, h, int(np.argmax(np.abs(h)))), {}
    if kind == "self_noise":
        power = _mean_power(x)
        n = _noise(x.shape, d["color"], d["seed"]) * math.sqrt(power / 10 ** (d["snr_db"] / 10))
        return x + n, {"noise_rms_db": 10 * math.log10(_mean_power(n)) if power > 0 else None}
    if kind == "gain":
        return x * 10.0 ** (d["gain_db"] / 20.0), {}
    if kind == "clipping":
        level = 10.0 ** (d["threshold_dbfs"] / 20.0)
        clipped = float(np.mean(np.abs(x) > level)) if x.size else 0.0
        return np.clip(x, -level, level), {"clipped_share": clipped}
    if kind == "resample":
        from sonicspec.audio.corpora import resample

        low = d["rate_hz"]
        if low >= rate_hz:
            return x.copy(), {"skipped": f"{low} Hz is not below the signal's {rate_hz} Hz"}
        y = resample(resample(x, rate_hz, low), low, rate_hz)[:, :x.shape[1]]
        return y, {}
    if kind in ("mp3", "opus", "gsm"):
        y, measured = encode_decode(x, rate_hz, kind, d.get("bitrate_kbps"))
        return y, measured
    raise AudioError(f"augmentation: unknown effect kind {kind!r} in a draw")


def apply_chain(draw: Sequence[Mapping[str, Any]], x: np.ndarray, rate_hz: int, *,
                target: bool = False,
                impulse_responses: Mapping[str, np.ndarray] | None = None,
                ) -> tuple[np.ndarray, list[dict[str, Any] | None]]:
    """``x`` ``(C, T)`` or ``(T,)`` through the drawn chain (:func:`draw_chain`): every
    effect drawn as applied (for a ``target``, only those marked ``targets``), in order.

    Returns the signal (float64, ``x``'s shape) and, per effect, what was measured on the way
    (codec bit rate, clipped share, noise level; ``None`` for an effect not applied).
    ``impulse_responses``: file name -> response at ``rate_hz`` (the caller reads them).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.atleast_2d(x)
    measured: list[dict[str, Any] | None] = []
    for d in draw:
        if not d["applied"] or (target and not d["targets"]):
            measured.append(None)
            continue
        y, m = _apply_one(d, y, rate_hz, impulse_responses or {})
        measured.append(m)
    return (y if x.ndim > 1 else y[0]), measured


@dataclass(frozen=True)
class GroupAugmentation:
    """A group's draw of the spec's augmentation chain (:func:`draw_chain`) and the impulse
    responses it may use (file as written -> response at the dataset's rate)."""

    draw: list[dict[str, Any]]
    impulse_responses: dict[str, np.ndarray]

    @property
    def touches_targets(self) -> bool:
        """Some applied effect is marked ``targets`` (the clean tracks go through it too)."""
        return any(d["applied"] and d["targets"] for d in self.draw)

    def apply(self, x: np.ndarray, rate: int, *, target: bool, full_scale: bool
              ) -> tuple[np.ndarray, list[dict[str, Any] | None]]:
        """``x`` through the draw; with ``full_scale`` (a PCM file without a per-file scale)
        clipped at 0 dBFS as the device's converter would, the share cut recorded."""
        y, measured = apply_chain(self.draw, x, rate, target=target,
                                  impulse_responses=self.impulse_responses)
        if full_scale:
            over = float(np.mean(np.abs(y) > 1.0)) if y.size else 0.0
            y = np.clip(y, -1.0, 1.0)
            measured = [*measured, {"full_scale_clipped_share": over}]
        return y, measured
