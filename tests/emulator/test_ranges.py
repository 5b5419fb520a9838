"""The SNR model reproduces the shape of the rmw_desert thesis' chapter 7 figures."""
from __future__ import annotations

import pytest

from uwgen.emulator.physics import SnrModel
from uwgen.emulator.sweep import (format_table, full_delivery_range, pdr_at, pdr_sweep,
                                  zero_delivery_distance)

DISTANCES = tuple(250.0 * i for i in range(8, 40))     # 2 km .. 9.75 km


@pytest.fixture(scope="module")
def sweep():
    return pdr_sweep(winds=(0.0, 5.0, 10.0), distances=DISTANCES, packets=300, seed=5)


@pytest.mark.parametrize("wind, thesis_km", [(0.0, 7.0), (5.0, 5.0), (10.0, 4.0)])
def test_full_delivery_up_to_the_thesis_range_for_each_wind(sweep, wind, thesis_km):
    full = full_delivery_range(sweep[wind]) / 1000
    assert thesis_km - 0.5 <= full <= thesis_km + 0.5


@pytest.mark.parametrize("wind", [0.0, 5.0, 10.0])
def test_delivery_falls_to_zero_within_about_a_kilometre(sweep, wind):
    full = full_delivery_range(sweep[wind])
    zero = zero_delivery_distance(sweep[wind])
    assert zero is not None
    assert 0 < zero - full <= 1500.0


@pytest.mark.parametrize("wind", [0.0, 5.0, 10.0])
def test_the_fall_is_steep_but_not_a_step(sweep, wind):
    partial = [p for p in sweep[wind] if 0.05 < p.pdr < 0.95]
    assert 1 <= len(partial) <= 5


def test_more_wind_shrinks_the_range(sweep):
    ranges = [full_delivery_range(sweep[w]) for w in (0.0, 5.0, 10.0)]
    assert ranges[0] > ranges[1] > ranges[2]
    assert ranges[0] - ranges[1] >= 1500.0          # "earlier by two kilometres"


def test_delivery_never_rises_with_distance_beyond_noise(sweep):
    for points in sweep.values():
        pdrs = [p.pdr for p in points]
        assert all(b <= a + 0.06 for a, b in zip(pdrs, pdrs[1:]))


def test_short_links_lose_nothing_even_with_strong_wind():
    point = pdr_at(1000.0, SnrModel(wind=15.0), packets=200)
    assert point.sent == 200 and point.delivered == 200


def test_table_lists_every_distance_and_wind(sweep):
    table = format_table(sweep)
    lines = table.splitlines()
    assert lines[0].split() == ["distance_km", "wind_0", "wind_5", "wind_10"]
    assert len([l for l in lines if l[:11].strip().replace(".", "").isdigit()]) == len(DISTANCES)
    assert "wind 10 m/s: full delivery" in table
