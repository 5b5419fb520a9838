"""The UW/PHYSICAL-like link budget: absorption, spreading, Wenz noise, BPSK errors."""
from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from uwgen.emulator.physics import (SnrModel, bpsk_per, noise_components_db, noise_power_db,
                                    noise_psd_db, thorp_db_per_km, transmission_loss_db)


@pytest.mark.parametrize("f_khz, published", [
    (1.0, 0.07),     # Thorp's absorption, dB/km, as tabulated in the literature
    (10.0, 1.19),
    (25.0, 6.1),
])
def test_thorp_absorption_matches_published_values(f_khz, published):
    assert thorp_db_per_km(f_khz) == pytest.approx(published, rel=0.05)


def test_absorption_grows_with_frequency():
    values = [thorp_db_per_km(f) for f in (0.1, 0.5, 1, 5, 10, 25, 50, 100)]
    assert values == sorted(values)


def test_practical_spreading_is_15_db_per_decade_plus_absorption():
    f = 25.0
    assert transmission_loss_db(1000.0, f) == pytest.approx(45.0 + thorp_db_per_km(f))
    # Over short ranges absorption is negligible and 10x the distance costs k * 10 dB.
    assert transmission_loss_db(100.0, f) - transmission_loss_db(10.0, f) == pytest.approx(
        15.0, abs=0.6)
    assert transmission_loss_db(100.0, f, spreading=2.0) - transmission_loss_db(
        10.0, f, spreading=2.0) == pytest.approx(20.0, abs=0.6)
    assert transmission_loss_db(0.0, f) == transmission_loss_db(1.0, f)


def test_each_wenz_noise_source_dominates_its_own_band():
    # Thesis chapter 2.2.2: turbulence only at the lowest frequencies, shipping 10-100 Hz,
    # wind-driven surface noise 100 Hz - 100 kHz, thermal noise above 100 kHz.
    def loudest(f_khz, wind=5.0, shipping=0.5):
        parts = noise_components_db(f_khz, wind, shipping)
        return max(parts, key=parts.get)
    assert loudest(0.002) == "turbulence"
    assert loudest(0.05) == "shipping"
    assert loudest(1.0) == "wind"
    assert loudest(25.0) == "wind"
    assert loudest(300.0) == "thermal"


def test_more_wind_or_shipping_means_more_noise():
    winds = [noise_psd_db(25.0, wind=w) for w in (0, 2, 5, 10, 15)]
    assert winds == sorted(winds) and winds[-1] - winds[0] > 20
    assert noise_psd_db(0.05, shipping=1.0) > noise_psd_db(0.05, shipping=0.0) + 15


def test_band_noise_power_is_about_psd_times_bandwidth():
    psd = noise_psd_db(25.0, wind=5.0)
    assert noise_power_db(25000.0, 5000.0, wind=5.0) == pytest.approx(
        psd + 10 * math.log10(5000.0), abs=0.5)


@given(st.floats(min_value=-10, max_value=30), st.integers(min_value=8, max_value=4000))
def test_bpsk_packet_error_rate_is_a_probability_falling_with_snr(snr_db, nbits):
    lo = bpsk_per(10 ** (snr_db / 10), nbits)
    hi = bpsk_per(10 ** ((snr_db + 1) / 10), nbits)
    assert 0.0 <= hi <= lo <= 1.0
    assert bpsk_per(10 ** (snr_db / 10), nbits * 2) >= lo


def test_snr_falls_with_distance_and_wind():
    calm, windy = SnrModel(wind=0.0), SnrModel(wind=10.0)
    assert calm.snr_db(1000) > calm.snr_db(5000) > calm.snr_db(9000)
    assert calm.snr_db(4000) - windy.snr_db(4000) == pytest.approx(
        windy.noise_db() - calm.noise_db())
    assert windy.noise_db() - calm.noise_db() > 20


@pytest.mark.parametrize("kwargs, message", [
    ({"shipping": 1.5}, "shipping"),
    ({"wind": -1.0}, "wind"),
    ({"bandwidth": 60000.0}, "bandwidth"),
    ({"spreading": 0.0}, "spreading"),
    ({"fading_db": -1.0}, "fading"),
])
def test_snr_model_refuses_impossible_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SnrModel(**kwargs)
