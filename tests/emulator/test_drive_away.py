"""`uwgen demo --drive-away`'s report: messages placed at the distance they were sent from."""
from __future__ import annotations

import pytest

from uwgen.demo.drive_away import by_distance, format_bins, plot, scenario


def test_messages_are_binned_by_the_distance_at_publication_and_matched_by_key():
    distance_at = lambda t: 100.0 * t          # noqa: E731 - 100 m/s away from the station
    sent = [(k, float(k)) for k in range(20)]                  # one message a second
    received = [(k, k + 0.5 + 0.01 * k) for k in range(20) if k < 8 and k % 4 != 3]
    bins = by_distance(sent, received, distance_at, width=500.0)
    assert [b.start for b in bins] == [0.0, 500.0, 1000.0, 1500.0]
    assert [b.sent for b in bins] == [5, 5, 5, 5]
    assert [b.delivered for b in bins] == [4, 2, 0, 0]
    assert bins[0].ratio == 0.8 and bins[2].ratio == 0.0
    assert bins[0].latency == pytest.approx(0.5 + 0.01 * 1.5)
    assert bins[2].latency is None
    assert "0.80" in format_bins("cmd", bins)


def test_a_key_sent_twice_is_left_out_and_a_reception_before_sending_is_not_a_delivery():
    bins = by_distance([("a", 0.0), ("a", 1.0), ("b", 2.0)], [("a", 1.5), ("b", 1.0)],
                       lambda t: 0.0)
    assert bins[0].sent == 1 and bins[0].delivered == 0


def test_the_scenario_waits_then_drives_straight_away(tmp_path):
    scen = scenario(300.0, 10300.0, 100.0, wind=0.0, seed=1)
    assert scen.position_at("vehicle", 10.0) == (300.0, 0.0, 0.0)
    assert scen.position_at("vehicle", 15.0 + 50.0) == pytest.approx((5300.0, 0.0, 0.0))
    assert scen.position_at("vehicle", 1e6) == (10300.0, 0.0, 0.0)
    bins = by_distance([(k, float(k)) for k in range(10)], [(k, k + 1.0) for k in range(5)],
                       lambda t: 1000.0 * t)
    png = plot({"cmd_vel": bins}, tmp_path / "away.png", "test")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_drive_runs_through_the_demos_phy_and_checks_where_it_fades():
    from uwgen.demo.drive_away import channel, expected_fade
    stock = scenario(300.0, 10300.0, 100.0, wind=0.0, seed=1)
    assert stock.snr.tx_power_db == 150.0                     # DESERT's stock PHY by default
    full, none = expected_fade(stock.snr)
    assert 3000.0 <= full <= 3400.0 and 3700.0 <= none <= 4000.0
    thesis = scenario(300.0, 10300.0, 100.0, wind=0.0, seed=1, phy_name="thesis")
    assert expected_fade(thesis.snr)[0] >= 6500.0
    with pytest.raises(ValueError, match="no SNR losses"):
        channel("none", 0.0)
