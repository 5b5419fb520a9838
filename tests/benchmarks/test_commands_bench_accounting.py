"""What benchmarks/commands_bench.py counts as a retry or an acknowledgement: its figures are
the byte goal's evidence, so its classifier is tested on real codec output."""
from __future__ import annotations

import importlib
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def bench():
    with pytest.MonkeyPatch.context() as mp:      # it imports commands_sim beside it
        mp.syspath_prepend(str(BENCHMARKS))
        yield importlib.import_module("commands_bench")


def test_a_result_status_of_fib_is_counted_as_one(bench):
    # wire-format 13's result status for handle 7, received and wanted (tests/codegen's bytes)
    for payload in (bytes.fromhex("0209181f00"), bytes.fromhex("0209181f01")):
        assert bench.result_status(bench.FIB_ID, payload)


@pytest.mark.parametrize("seq", [24, 232, 255])
def test_an_echo_request_whose_seq_opens_like_a_result_status_is_a_request(bench, seq):
    # kind 2, id 20, seq 24..255 is CBOR `18 xx`: the third byte of a result status too
    payload = bytes([2, bench.ECHO_ID, 0x18, seq, 0xF9, 0, 0])
    assert payload[2] == 0x18 and not bench.result_status(bench.ECHO_ID, payload)


def test_each_sides_losses_are_what_the_peer_lost_of_what_it_sent(bench):
    # the emulator counts a loss at the node the packet was addressed to
    counters = {"surface": {"lost_per": 139, "packets_sent": 1276},
                "vehicle": {"lost_per": 247, "packets_sent": 572}}
    assert bench.channel_losses(counters) == {"surface": (247, 1276), "vehicle": (139, 572)}


def test_the_floor_at_the_seen_rates_weighs_each_sides_first_copies_by_its_own_losses(bench):
    losses = {"surface": (1, 5), "vehicle": (1, 2)}        # 20 % and 50 % erased
    assert bench.floor_at({"surface": 400, "vehicle": 100}, losses) == 100 + 100
    assert bench.floor_at({"surface": 400}, {"surface": (0, 0)}) == 0   # nothing sent
