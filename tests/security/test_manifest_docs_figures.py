"""The seal's costs as the sample manifests' comments state them are recomputed from the code's
constants (wire-format.md sections 12, 12.2 and 12.3), so the docs cannot drift from the bytes."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from uwgen.runtime.link.packets import envelope_room
from uwgen.runtime.wire import envelope as env
from uwgen.security import wire
from uwgen.security.packet_seal import ASK_BYTES, SYNC_ANSWER, SYNC_BYTES, max_overhead
from uwgen.security.side import SYNC_EVERY, SYNC_FIRST, SYNC_PERIOD

SAMPLES = Path(__file__).resolve().parents[2] / "msg_samples"
TAG = env.TAG_LEN                               # the default per-packet tag
AVERAGE = TAG + SYNC_BYTES / SYNC_EVERY         # bytes per packet on a busy link (section 12.2)


def comments(name: str) -> str:
    """The comment text of a sample manifest, its lines joined by single spaces."""
    text = " ".join(line.split("#", 1)[1] for line in (SAMPLES / name).read_text(encoding="utf-8").splitlines()
                    if "#" in line)
    return re.sub(r"\s+", " ", text)


def air(nbytes: float, bitrate: float) -> float:
    return nbytes * 8 / bitrate


REFERENCE = [
    f"one {TAG}-byte tag per packet",
    f"Sync packets carry {SYNC_BYTES} bytes more",
    f"{TAG + SYNC_BYTES} in all",
    f"the first {SYNC_FIRST} packets after a start, 1 in {SYNC_EVERY} after that",
    f"the first after {SYNC_PERIOD:g} s without one",
    f"the next {SYNC_ANSWER} after a peer asked for one",
    f"pays {ASK_BYTES} bytes more, {max_overhead()}",
    f"On average {AVERAGE:.1f} bytes per packet",
    f"{wire.OVERHEAD} bytes per payload (a {wire.WORD_BYTES}-byte sender and number word, "
    f"an {wire.TAG_BYTES}-byte tag), {wire.SYNC_OVERHEAD} on sync frames",
]

DEMO = [
    f"one {TAG}-byte tag, {TAG + SYNC_BYTES} bytes on a sync packet (1 in {SYNC_EVERY}, "
    f"and the first {SYNC_FIRST} after a start)",
    f"{AVERAGE:.1f} on average: {air(AVERAGE, 4800):.3f} s of air time at this link's 4800 bit/s, "
    f"{air(AVERAGE, 200):.2f} s at 200 bit/s, and {TAG} of each 64-byte packet's bytes",
    f"(a tag of {TAG} bytes, {TAG + SYNC_BYTES} on a sync packet, {max_overhead()} when it asks for one), "
    f"which leaves {envelope_room(64, max_overhead())} bytes of messages",
]


@pytest.mark.parametrize("figure", REFERENCE)
def test_the_manifest_reference_states_the_seal_as_the_code_builds_it(figure):
    assert figure in comments("manifest-reference.yaml")


@pytest.mark.parametrize("figure", DEMO)
def test_the_demo_manifest_states_the_seal_as_the_code_builds_it(figure):
    assert figure in comments("uwgen.yaml")


def test_the_figure_check_sees_a_stale_figure():
    stale = comments("manifest-reference.yaml").replace(f"1 in {SYNC_EVERY}", "1 in 32")
    assert REFERENCE[3] not in stale
