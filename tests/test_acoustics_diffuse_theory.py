"""Exact references of isotropic noise fields (``theory``): sinc(kd), J0(kd) and the
Brown–Duda head's interaural coherence, checked against independent integrals (issue 30)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.directions import fibonacci_sphere
from sonicspec.acoustics.receivers.hrtf import SphereHead, sphere_head_coherence
from sonicspec.acoustics.theory import (
    brown_duda_diffuse_coherence,
    brown_duda_response,
    cylindrical_isotropic_coherence,
    spherical_isotropic_coherence,
)
from sonicspec.errors import AcousticsError

C = 343.0


@pytest.mark.parametrize("d", [0.05, 0.1, 0.2])
def test_sinc_is_the_mean_of_plane_waves_over_the_sphere(d):
    f = np.linspace(0, 8000, 81)
    k = 2 * math.pi * f / C
    dirs = fibonacci_sphere(40_000)
    # E[e^{jk d·Ω}] over uniform Ω, capsules d apart along a slanted axis.
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    numeric = np.cos(k[:, None] * d * (dirs @ axis)[None, :]).mean(axis=1)
    exact = spherical_isotropic_coherence(f, d, C)
    assert np.max(np.abs(numeric - exact)) < 1e-3
    assert exact[0] == 1.0


@pytest.mark.parametrize("d", [0.05, 0.1, 0.2])
def test_j0_is_the_mean_of_horizontal_plane_waves(d):
    f = np.linspace(0, 8000, 81)
    k = 2 * math.pi * f / C
    phi = 2 * math.pi * np.arange(720) / 720
    numeric = np.cos(k[:, None] * d * np.cos(phi)[None, :]).mean(axis=1)
    assert np.max(np.abs(numeric - cylindrical_isotropic_coherence(f, d, C))) < 1e-9
    # The two fields differ: the cylindrical coherence decays more slowly (1/√kd vs 1/kd).
    far = f > 3000
    assert np.max(np.abs(cylindrical_isotropic_coherence(f, d, C)[far])) > np.max(
        np.abs(spherical_isotropic_coherence(f, d, C)[far]))


def test_brown_duda_response_limits():
    # Unity at DC; at high frequency the lit ear (θ = 0) rises to α = 2 (+6 dB) and the
    # deepest shadow (θ = θ_min = 150°) falls to α_min = 0.1 (−20 dB).
    h = brown_duda_response([0.0, 1e7], np.array([1.0, math.cos(math.radians(150))]),
                            0.0875, C)
    assert np.allclose(np.abs(h[0]), 1.0)
    assert abs(abs(h[1, 0]) - 2.0) < 1e-3
    assert abs(abs(h[1, 1]) - 0.1) < 1e-3
    # The low-frequency lag of a lateral wave between the ears: Woodworth's (a/c)(π/2 + 1)
    # plus the shadow filters' group delays, (α_near − α_far) a / (2c).
    f = np.array([1.0])
    near, far = (brown_duda_response(f, cos, 0.0875, C) for cos in (1.0, -1.0))
    lag = -np.angle(far[0] / near[0]) / (2 * math.pi)
    alpha_far = 1.05 + 0.95 * math.cos(math.pi * 180 / 150)
    expected = 0.0875 / C * (math.pi / 2 + 1) + (2.0 - alpha_far) * 0.0875 / (2 * C)
    assert lag == pytest.approx(expected, rel=1e-4)


def test_head_coherence_matches_the_receivers_own_sum():
    # The receiver's Fibonacci sum of its digital filters (hrtf.sphere_head_coherence) and
    # the product-quadrature integral of the same model agree.
    fs = 16000
    f = np.linspace(50, 7000, 60)
    exact = brown_duda_diffuse_coherence(f, 0.0875, 100.0, sample_rate_hz=fs, speed_of_sound_m_s=C)
    fib = sphere_head_coherence(SphereHead(0.0875, 100.0), f, fs, speed_of_sound_m_s=C,
                                n_directions=8192)
    assert np.max(np.abs(exact - fib)) < 0.01
    assert exact[0] > 0.98 and np.min(exact) < 0.2


def test_head_coherence_limits():
    f = np.array([0.0, 200.0, 2000.0])
    # Both ears at one point: fully coherent at every frequency.
    same = brown_duda_diffuse_coherence(f, 0.0875, 0.0)
    assert np.allclose(same, 1.0)
    cyl = brown_duda_diffuse_coherence(np.linspace(50, 4000, 40), field="cylindrical")
    sph = brown_duda_diffuse_coherence(np.linspace(50, 4000, 40), field="spherical")
    assert np.max(np.abs(cyl - sph)) > 0.05  # the two fields differ


def test_bad_inputs_are_named():
    with pytest.raises(AcousticsError, match="distance_m: expected a distance >= 0"):
        spherical_isotropic_coherence([100.0], -1.0)
    with pytest.raises(AcousticsError, match="frequencies_hz: expected finite"):
        cylindrical_isotropic_coherence([np.nan], 0.1)
    with pytest.raises(AcousticsError, match="field: expected 'spherical' or 'cylindrical'"):
        brown_duda_diffuse_coherence([100.0], field="planar")
    with pytest.raises(AcousticsError, match="Nyquist"):
        brown_duda_response([9000.0], 1.0, 0.0875, sample_rate_hz=16000)
