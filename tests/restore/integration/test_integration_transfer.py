"""Transfer functions against their closed forms (patent formulas)."""
import numpy as np
import pytest

from restore.integration.transfer import (blind_frequencies, chain_gain, fused_chain_gain,
                                          fused_gains, noise_gain, pair_transfer, wiener_gain)

F = np.linspace(0, 600, 2401)
TAU = 7.4e-3


def test_pair_transfer_is_the_shift_operator():
    # theta(t) = cos(2 pi f t): theta(t + tau) - theta(t) = Re(G e^{j w t})
    f, t = 37.0, np.linspace(0, 0.1, 50)
    g = pair_transfer(f, TAU)
    np.testing.assert_allclose(np.cos(2 * np.pi * f * (t + TAU)) - np.cos(2 * np.pi * f * t),
                               np.real(g * np.exp(2j * np.pi * f * t)), atol=1e-12)
    np.testing.assert_allclose(np.abs(pair_transfer(F, TAU)) ** 2,
                               2 * (1 - np.cos(2 * np.pi * F * TAU)), atol=1e-12)


def test_wiener_and_chain_gain():
    k = 0.1
    h = wiener_gain(F, TAU, k)
    w = 2 * np.pi * F
    np.testing.assert_allclose(h, (np.exp(-1j * w * TAU) - 1) / (2 * (1 - np.cos(w * TAU)) + k),
                               atol=1e-12)
    fk = chain_gain(F, TAU, k)
    np.testing.assert_allclose(fk, np.real(h * pair_transfer(F, TAU)), atol=1e-12)
    np.testing.assert_allclose(np.imag(h * pair_transfer(F, TAU)), 0, atol=1e-12)  # no phase
    assert np.all((fk >= 0) & (fk <= 1))
    # maximum 4 / (4 + k) at odd multiples of 1 / (2 tau)
    assert chain_gain(0.5 / TAU, TAU, k) == pytest.approx(4 / (4 + k))


def test_blind_frequencies():
    b = blind_frequencies(TAU, 600)
    np.testing.assert_allclose(b, np.arange(5) / TAU)
    np.testing.assert_allclose(np.abs(pair_transfer(b, TAU)), 0, atol=1e-12)
    np.testing.assert_allclose(chain_gain(b, TAU, 0.1), 0, atol=1e-12)
    with pytest.raises(ValueError, match="^tau_s"):
        blind_frequencies(-1, 10)


def test_fused_gains_single_pair_and_filling():
    h1 = fused_gains(F, [TAU], k=0.1)
    np.testing.assert_allclose(h1[0], wiener_gain(F, TAU, 0.1), atol=1e-12)
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    fc = fused_chain_gain(F, taus, k=0.1)
    g2 = sum(np.abs(pair_transfer(F, t)) ** 2 for t in taus)
    np.testing.assert_allclose(fc, g2 / (g2 + 0.1), atol=1e-12)
    # at the blind frequencies of the 22.2 ms pair (45 Hz, 90 Hz) the others fill in
    for fb in (1 / 22.2e-3, 2 / 22.2e-3):
        assert chain_gain(fb, 22.2e-3, 0.1) == pytest.approx(0, abs=1e-12)
        assert fused_chain_gain(fb, taus, k=0.1)[0] > 0.9
    # ... but n / 7.4 ms is blind for all three
    assert fused_chain_gain(1 / 7.4e-3, taus, k=0.1)[0] == pytest.approx(0, abs=1e-9)


def test_fused_gains_with_psd_equals_constant_k():
    taus = [7.4e-3, 22.2e-3]
    s = np.full(F.shape, 2.0)
    h = fused_gains(F, taus, signal_psd=s, noise_psd=[0.2, 0.2])
    np.testing.assert_allclose(h, fused_gains(F, taus, k=0.1), atol=1e-12)
    ng = noise_gain(F, taus, k=0.1)
    assert np.all(ng >= 0)
    with pytest.raises(ValueError, match="^k"):
        fused_gains(F, taus)
    with pytest.raises(ValueError, match="^k"):
        wiener_gain(F, TAU, -1)
