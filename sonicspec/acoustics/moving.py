"""Moving sources and receivers rendered as time-varying delays (issue 18's method).

One propagation path (the direct sound, or one image source, which moves as the mirror of the
source) from a source at ``x_s(t)`` to a receiver at ``x_r(t)``: the sound heard at output
sample ``j`` left the source at the emission time ``u(j)`` solving the retarded-time equation
(:func:`~sonicspec.acoustics.theory.moving_arrival_times`, inverted by interpolation: arrival
times grow monotonically for any subsonic motion). Then

    y[j] = s(u(j)) · g(u) / (4π r(u)) · du/dj,

``s(u)`` the dry signal read at the fractional index ``u`` through a Kaiser-windowed sinc of
±8 samples (β = 6), ``du/dj`` the density of arrivals (the Doppler factor the exact Dirac sum
carries, :func:`~sonicspec.acoustics.theory.moving_point_source`). The delay, the level and
the Doppler shift are those of the geometry at every output sample: no crossfade, so no comb
filter.

The interpolator was chosen by measurement against the exact moving point source (a walk at
1.5 m/s past a microphone 1 m away, pink noise to 0.8 × Nyquist): SNR 28 / 37 / 64 / 102 dB
and worst smoothed dip −1.2 / −0.13 / −0.01 / −0.001 dB for ±2 / ±4 / ±8 / ±16 taps (β tuned
for ±8: 53–64 dB over β 4–8). ±8 clears issue 18's bar (SNR ≥ 30 dB, dips ≥ −1 dB) with a wide
margin at half the cost of ±16.
"""

from __future__ import annotations

import numpy as np

from sonicspec.acoustics.theory import moving_arrival_times, windowed_sinc
from sonicspec.errors import AcousticsError
from sonicspec.units import SPEED_OF_SOUND_M_S

HALF_WIDTH = 8
KAISER_BETA = 6.0


def render_path(dry, source_m, receiver_m, sample_rate_hz: float, *,
                speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S, gain=1.0, n_out: int | None = None,
                half_width: int = HALF_WIDTH, beta: float = KAISER_BETA) -> np.ndarray:
    """One propagation path of a moving source to a (moving) receiver, ``(n_out,)``.

    Parameters
    ----------
    dry : (n,) float
        The source signal at its emission times ``k / fs``.
    source_m : (3,) or (n, 3) float
        The (image) source's position at each emission time, metres.
    receiver_m : (3,) or (m, 3) float
        The receiver's position at each output sample time, metres.
    sample_rate_hz : float
        Rate of ``dry`` and of the output.
    speed_of_sound_m_s : float
        Speed of sound.
    gain : float or (n,) float
        Path gain per emission (reflection coefficients of an image source).
    n_out : int, optional
        Output length; default: up to the last arrival.
    half_width, beta : int, float
        The windowed sinc's half width (taps each side) and Kaiser β.
    """
    s = np.asarray(dry, dtype=np.float64)
    if s.ndim != 1 or s.size < 2:
        raise AcousticsError(f"dry: expected a 1-D signal of >= 2 samples, got shape {s.shape}")
    fs = float(sample_rate_hz)
    t_a, r = moving_arrival_times(source_m, receiver_m, s.size, fs, speed_of_sound_m_s)
    if np.any(r <= 0):
        raise AcousticsError("source_m: the source passes through the receiver (r = 0)")
    tau = t_a * fs  # arrival of each emission, output samples (increasing)
    if n_out is None:
        n_out = int(np.ceil(tau[-1])) + half_width + 1
    j = np.arange(n_out, dtype=np.float64)
    k = np.arange(s.size, dtype=np.float64)
    u = np.interp(j, tau, k)  # emission index heard at each output sample
    density = np.interp(j, tau, 1.0 / np.gradient(tau))
    amp = np.broadcast_to(np.asarray(gain, dtype=np.float64), s.shape) / (4 * np.pi * r)
    acc = np.zeros(n_out)
    base = np.floor(u).astype(np.int64)
    for offset in range(-half_width + 1, half_width + 1):
        m = base + offset
        ok = (m >= 0) & (m < s.size)
        acc[ok] += s[m[ok]] * windowed_sinc(u[ok] - m[ok], half_width, beta)
    # Before the first arrival and after the last the path is silent (u is clamped there;
    # the sinc's own reach covers the edges).
    heard = (j >= tau[0] - half_width) & (j <= tau[-1] + half_width)
    return np.where(heard, acc * np.interp(u, k, amp) * density, 0.0)
