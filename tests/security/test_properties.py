"""Properties: whatever the message and whatever is changed in its protected frame, the
receiver takes the real frame once and nothing else."""
from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.runtime.wire.codec import pack_items

from .helpers import passes_to_bridge, surface, vehicle

texts = st.text(max_size=300)
changes = st.lists(st.tuples(st.integers(min_value=0), st.integers(min_value=1, max_value=255)),
                   min_size=1, max_size=4)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=texts, ident=st.sampled_from([7, 20]), change=changes, cut=st.integers(0, 3))
def test_any_change_to_a_protected_frame_is_rejected(text, ident, change, cut):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        s, v = surface(folder), vehicle(folder)
        payload = pack_items([0, 7, text]) if ident == 7 else pack_items([2, 20, len(text), text])
        good = s.protect(ident, payload)
        bad = bytearray(good)
        for pos, mask in change:
            bad[pos % len(bad)] ^= mask
        bad = bytes(bad[:len(bad) - cut]) if cut else bytes(bad)
        if bad != good:
            assert not passes_to_bridge(v.unprotect(bad))
        assert v.unprotect(good) == payload                 # once...
        assert v.unprotect(good) is None                    # ...and only once


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(order=st.lists(st.integers(0, 199), max_size=400), restart_at=st.integers(0, 400),
       epoch_numbers=st.sampled_from([10, 1 << 16]))
def test_any_order_of_recorded_frames_delivers_each_at_most_once(order, restart_at, epoch_numbers):
    # An attacker delivers, drops, repeats and reorders 200 recorded frames at will, and the
    # receiver restarts (without any state) somewhere in between: before the restart each frame
    # is delivered at most once and unchanged; after it, none (all were sealed before it).
    from uwgen.runtime.clock import ManualClock

    from .helpers import WALL0, twist
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        wall = ManualClock(WALL0)
        v = vehicle(folder, wall=wall)
        s = surface(folder, wall=wall, epoch_numbers=epoch_numbers)
        frames = [s.protect(4, twist(float(i))) for i in range(200)]
        before: list[bytes] = []
        after: list[bytes] = []
        for k, i in enumerate(order):
            if k == restart_at:
                v.close()
                wall.advance(0.5)
                v = vehicle(folder, wall=wall)
            got = v.unprotect(frames[i])
            if got is not None:
                (before if k < restart_at else after).append(got)
        assert len(before) == len(set(before))
        assert set(before) <= {twist(float(i)) for i in range(200)}
        assert after == []
