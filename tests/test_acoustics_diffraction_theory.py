"""The exact wedge and half-plane (``theory.Wedge``, Biot–Tolstoy–Medwin / Macdonald): the
reference edge diffraction is measured against (issue 19), checked against published limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonicspec.acoustics.theory import (
    Wedge,
    edge_path_length_m,
    keller_wedge_diffraction,
    wedge_diffraction_ir,
    wedge_diffraction_spectrum,
    wedge_geometric_field,
)
from sonicspec.errors import AcousticsError

C = 343.0
SCREEN = Wedge.half_plane([0, 0, 0], [0, 0, 1], [0, -1, 0])
CORNER = Wedge([0.2, 0.1, 0], [0, 0, 1], [1, 0, 0], 1.5 * math.pi)



def free_field(source, receiver, f) -> np.ndarray:
    r = float(np.linalg.norm(np.asarray(source) - np.asarray(receiver)))
    return np.exp(-2j * np.pi * np.asarray(f) / C * r) / (4 * np.pi * r)


def total_db(wedge, source, receiver, f) -> np.ndarray:
    total = (wedge_diffraction_spectrum(wedge, source, receiver, f, C)
             + wedge_geometric_field(wedge, source, receiver, f, C))
    return 20 * np.log10(np.abs(total) / np.abs(free_field(source, receiver, f)))


def test_cylindrical_coordinates_and_edge_path() -> None:
    p = CORNER.at(1.3, 200.0, -0.4)
    r, th, z = CORNER.cylindrical(p)
    assert (r, math.degrees(th), z) == pytest.approx((1.3, 200.0, -0.4))
    src, rcv = CORNER.at(1.0, 30, 0.5), CORNER.at(2.0, 250, -1.0)
    assert edge_path_length_m(CORNER, src, rcv) == pytest.approx(math.hypot(3.0, 1.5))


def test_half_plane_at_the_shadow_boundary_is_minus_6_db_from_both_sides() -> None:
    # Source 1 m from the edge at θ = 60°, receiver 2 m away on the shadow boundary θ = 240°,
    # approached from the lit side and the shadow side: the total field is continuous and
    # tends to half the free field (−6.02 dB) as kL grows (Sommerfeld; Pierce, Acoustics §9.4).
    src = SCREEN.at(1.0, 60.0, 0.0)
    f = np.array([4000.0, 16000.0])
    lit = total_db(SCREEN, src, SCREEN.at(2.0, 240.0 - 1e-4, 0.0), f)
    shadow = total_db(SCREEN, src, SCREEN.at(2.0, 240.0 + 1e-4, 0.0), f)
    on = total_db(SCREEN, src, SCREEN.at(2.0, 240.0, 0.0), f)
    assert np.max(np.abs(lit - shadow)) < 0.02
    assert np.max(np.abs(on - shadow)) < 0.02
    assert shadow[1] == pytest.approx(-6.02, abs=0.25)
    assert abs(shadow[1] + 6.02) < abs(shadow[0] + 6.02) + 0.01  # converging with frequency


def test_the_field_is_continuous_across_a_reflection_boundary() -> None:
    # The 270° corner's face-0 reflection boundary θ_R = π − θ_S: the reflection switches off,
    # the diffracted wave jumps by half of it with the opposite sign.
    src = CORNER.at(1.5, 40.0, 0.2)
    f = np.array([500.0, 2000.0])
    before = total_db(CORNER, src, CORNER.at(1.0, 140.0 - 1e-4, -0.3), f)
    after = total_db(CORNER, src, CORNER.at(1.0, 140.0 + 1e-4, -0.3), f)
    np.testing.assert_allclose(before, after, atol=0.02)
    jump = (wedge_diffraction_spectrum(CORNER, src, CORNER.at(1.0, 140.0 + 1e-4, -0.3), f, C)
            - wedge_diffraction_spectrum(CORNER, src, CORNER.at(1.0, 140.0 - 1e-4, -0.3), f, C))
    refl_len = math.hypot(2.5, 0.5)
    np.testing.assert_allclose(np.abs(jump), 1 / (4 * math.pi * refl_len), rtol=2e-3)


def test_reciprocity_swapping_source_and_receiver() -> None:
    a, b = CORNER.at(0.7, 20.0, 0.9), CORNER.at(2.4, 230.0, -0.6)
    f = np.array([125.0, 1000.0, 6000.0])
    np.testing.assert_allclose(wedge_diffraction_spectrum(CORNER, a, b, f, C),
                               wedge_diffraction_spectrum(CORNER, b, a, f, C), rtol=1e-7)
    np.testing.assert_allclose(wedge_diffraction_ir(CORNER, a, b, 48000, 2000, C),
                               wedge_diffraction_ir(CORNER, b, a, 48000, 2000, C),
                               rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("wedge", [SCREEN, CORNER], ids=["half-plane", "corner-270"])
def test_far_in_the_shadow_the_exact_field_tends_to_kellers_gtd(wedge: Wedge) -> None:
    src = wedge.at(1.5, 30.0, 0.0)
    rcv = wedge.at(2.5, wedge.open_angle * 180 / math.pi - 20.0, 0.8)
    f = np.array([250.0, 2000.0, 16000.0])
    err = np.abs(20 * np.log10(np.abs(wedge_diffraction_spectrum(wedge, src, rcv, f, C)
                                      / keller_wedge_diffraction(wedge, src, rcv, f, C))))
    assert err[-1] < 0.1
    assert err[0] > err[1] > err[-1]  # an asymptote: better the higher k r


def test_impulse_response_onset_and_its_spectrum() -> None:
    src, rcv = SCREEN.at(1.0, 60.0, 0.3), SCREEN.at(2.0, 250.0, -0.5)
    fs, n = 96000, 48000
    h = wedge_diffraction_ir(SCREEN, src, rcv, fs, n, C)
    onset = edge_path_length_m(SCREEN, src, rcv) / C * fs
    assert np.all(h[: math.floor(onset - 0.5)] == 0)
    assert abs(int(np.argmax(np.abs(h))) - onset) <= 1
    f = np.array([125.0, 500.0, 2000.0])
    spectrum = np.exp(-2j * np.pi * np.outer(f, np.arange(n)) / fs) @ h
    # Each sample holds its interval's integral but is timed at its centre: where h is steep
    # (the 1/√(t − τ₀) onset) that costs up to ω/(2 fs) of phase on the onset's share.
    np.testing.assert_allclose(spectrum, wedge_diffraction_spectrum(SCREEN, src, rcv, f, C),
                               rtol=6e-3)


def test_bad_wedges_and_points_are_named() -> None:
    with pytest.raises(AcousticsError, match=r"open_angle: expected a value in \(π, 2π\]"):
        Wedge([0, 0, 0], [0, 0, 1], [1, 0, 0], 0.5 * math.pi)
    with pytest.raises(AcousticsError, match="face0: expected a direction not along the edge"):
        Wedge([0, 0, 0], [0, 0, 1], [0, 0, 2], math.pi * 1.5)
    with pytest.raises(AcousticsError, match="inside the wedge"):
        CORNER.cylindrical(CORNER.at(1.0, 300.0, 0.0))
    with pytest.raises(AcousticsError, match="on the wedge's edge"):
        SCREEN.cylindrical([0, 0, 3.0])
