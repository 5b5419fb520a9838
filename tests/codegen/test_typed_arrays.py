"""Numeric arrays as RFC 8746 typed arrays (wire-format.md section 4.1): the page's worked
bytes, the choice that is never larger than the items, both forms decoded, bad typed arrays
refused with the field's path, and none of them in profile rmw_desert."""
from __future__ import annotations

import array
import math
import random
import re
from pathlib import Path
from unittest import mock

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import BatteryState, ChannelFloat32, LaserScan
from std_msgs.msg import Int16MultiArray

from uwgen.codegen import generate
from uwgen.runtime.wire import typed_arrays as rt
from uwgen.runtime.wire.codec import DecodeError, pack_items

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"
TYPES = ["sensor_msgs/msg/ChannelFloat32", "std_msgs/msg/Int16MultiArray", "sensor_msgs/msg/LaserScan",
         "sensor_msgs/msg/BatteryState", "geometry_msgs/msg/PoseWithCovariance"]
EXAMPLES = {
    "halves": ChannelFloat32(name="r", values=[0.5, 1.5, 100.0]),
    "singles": ChannelFloat32(name="r", values=[3.95, 0.1]),
    "items": ChannelFloat32(name="r", values=[0.0, 3.95]),
    "empty": ChannelFloat32(name="r", values=[]),
    "int16": Int16MultiArray(data=[1000, -1000, 300]),
    "int16-small": Int16MultiArray(data=[1, 2, 3]),
}


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("typed"), "uwgen_typed", names=TYPES, profiles=("native", "rmw_desert"))


def doc_rows() -> dict[str, tuple[str, str]]:
    """example -> (payload hex, the 'sent' column), from section 4.1's table."""
    section = DOC.read_text().split("### 4.1", 1)[1].split("\n## ", 1)[0].split("\n### ", 1)[0]
    rows = re.findall(r"^\| ([a-z0-9-]+) \| [^|]+ \| `([0-9A-F ]+)` \| ([^|]+) \|$", section, re.M)
    return {name: (payload, sent.strip()) for name, payload, sent in rows}


def test_every_example_row_of_section_4_1_is_checked():
    assert set(doc_rows()) == set(EXAMPLES)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_section_4_1_worked_bytes_and_sizes(pkg, name):
    msg = EXAMPLES[name]
    codec = pkg.codec(f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}")
    payload = codec.encode(msg, [0, 4])
    want, sent = doc_rows()[name]
    assert payload.hex(" ").upper() == want
    # The sizes the 'sent' column states, recomputed from the formulas of the section.
    values = list(msg.values if isinstance(msg, ChannelFloat32) else msg.data)
    n, w = len(values), (4 if isinstance(msg, ChannelFloat32) else 2)
    h = rt.head_size
    sizes = {"I": len(pack_items([n, *values])), "T": 2 + h(w * n) + w * n, "H": 2 + h(2 * n) + 2 * n}
    for letter, stated in re.findall(r"([ITH]) = (\d+)", sent):
        assert sizes[letter] == int(stated), (letter, sizes)
    back, _ = codec.decode(payload, (0, 4))
    assert list(back.values if isinstance(msg, ChannelFloat32) else back.data) == \
        [float(array.array("f", [v])[0]) if w == 4 else v for v in values]


def scan(ranges, intensities) -> LaserScan:
    return LaserScan(angle_min=-1.0, angle_max=1.0, range_max=30.0, ranges=ranges, intensities=intensities)


def items_of(pkg, msg, type_name) -> list:
    return cbor2.loads(b"\x9f" + pkg.codec(type_name).encode(msg, [0, 4]) + b"\xff")


def test_laser_ranges_travel_as_float32_and_integer_intensities_as_halves(pkg):
    msg = scan([0.5 + 20 * abs(math.sin(k * 0.05)) for k in range(360)], [float(100 + k % 50) for k in range(360)])
    tags = [item.tag for item in items_of(pkg, msg, "sensor_msgs/msg/LaserScan") if isinstance(item, cbor2.CBORTag)]
    assert tags == [85, 84]
    payload = pkg.codec("sensor_msgs/msg/LaserScan").encode(msg, [0, 4])
    back, _ = pkg.codec("sensor_msgs/msg/LaserScan").decode(payload, (0, 4))
    assert back.ranges == array.array("f", msg.ranges) and back.intensities == msg.intensities
    assert type(back.ranges) is array.array and back.ranges.typecode == "f"


def test_a_covariance_of_mostly_zeros_stays_items_and_an_exact_one_goes_typed(pkg):
    from geometry_msgs.msg import PoseWithCovariance

    name = "geometry_msgs/msg/PoseWithCovariance"
    sparse = PoseWithCovariance(covariance=[0.05 if k % 7 == 0 else 0.0 for k in range(36)])
    assert not any(isinstance(i, cbor2.CBORTag) for i in items_of(pkg, sparse, name))
    dense = PoseWithCovariance(covariance=[1 / (k + 3) for k in range(36)])
    assert [i.tag for i in items_of(pkg, dense, name) if isinstance(i, cbor2.CBORTag)] == [86]
    for msg in (sparse, dense):
        back, _ = pkg.codec(name).decode(pkg.codec(name).encode(msg, [0, 4]), (0, 4))
        assert list(back.covariance) == list(msg.covariance)


FLOATS = st.one_of(st.sampled_from([0.0, -0.0, 1.0, 0.5, 100.0, 65504.0, 1e-45, 2.0 ** -24, math.inf, -math.inf]),
                   st.floats(width=32, allow_nan=False))


@settings(max_examples=300, deadline=None)
@given(values=st.lists(FLOATS, max_size=60), code=st.sampled_from("fd"), counted=st.booleans())
def test_the_choice_is_never_larger_than_the_items_and_decodes_back(values, code, counted):
    got = rt.number_array(values, code, counted, "x")
    items = ([len(values)] if counted else []) + array.array(code, values).tolist()
    assert len(pack_items([0, *got])) <= len(pack_items([0, *items]))
    typed = 2 + rt.head_size(len(values) * (4 if code == "f" else 8)) + len(values) * (4 if code == "f" else 8)
    if typed <= len(pack_items([0, *items])) - 1:
        assert isinstance(got[0], cbor2.CBORTag)       # typed wherever no larger
    if got and isinstance(got[0], cbor2.CBORTag):
        back = rt.typed_array(got[0], code, "x", None, False).tolist()
        assert array.array(code, back).tobytes() == array.array(code, values).tobytes()


def test_without_numpy_halves_convert_the_same(monkeypatch):
    values = [float(k % 40) for k in range(200)]
    with_numpy = rt.number_array(values, "f", True, "x")
    monkeypatch.setattr(rt, "_np", None)
    without = rt.number_array(values, "f", True, "x")
    assert with_numpy == without and without[0].tag == 84
    assert rt.typed_array(without[0], "f", "x", None, False).tolist() == values


def test_both_forms_of_the_same_array_decode_to_the_same_message(pkg):
    codec = pkg.codec("sensor_msgs/msg/ChannelFloat32")
    as_items = pack_items([0, 4, "r", 2, 3.5, 0.25])
    typed = pack_items([0, 4, "r", cbor2.CBORTag(85, array.array("f", [3.5, 0.25]).tobytes())])
    halves = pack_items([0, 4, "r", cbor2.CBORTag(84, bytes.fromhex("00 43 00 34"))])
    decoded = [list(codec.decode(p, (0, 4))[0].values) for p in (as_items, typed, halves)]
    assert decoded == [[3.5, 0.25]] * 3


@pytest.mark.parametrize("item, message", [
    (cbor2.CBORTag(86, bytes(8)), "expected a typed array (tag 85 or, for floats, 84"),
    (cbor2.CBORTag(85, bytes(6)), "not a whole number of 4-byte elements"),
    (cbor2.CBORTag(84, bytes(3)), "not a whole number of 2-byte elements"),
    (cbor2.CBORTag(85, "text"), "got tag 85"),
])
def test_a_bad_typed_array_is_refused_with_the_field_path(pkg, item, message):
    codec = pkg.codec("sensor_msgs/msg/ChannelFloat32")
    with pytest.raises(DecodeError) as err:
        codec.decode(pack_items([0, 4, "r", item]), (0, 4))
    assert err.value.path == "values" and message in str(err.value)


def test_a_typed_fixed_array_must_have_its_size(pkg):
    name = "geometry_msgs/msg/PoseWithCovariance"
    good = items_of(pkg, __import__("geometry_msgs.msg").msg.PoseWithCovariance(), name)
    short = [*good[:-1], cbor2.CBORTag(86, bytes(8 * 35))]
    with pytest.raises(DecodeError, match="35 elements in a fixed array of 36") as err:
        pkg.codec(name).decode(pack_items(short), (0, 4))
    assert err.value.path == "covariance"


def test_profile_rmw_desert_never_sends_a_typed_array(pkg):
    msg = BatteryState(cell_voltage=[3.95, 3.96, 3.94, 3.95], cell_temperature=[21.0, 21.5, 22.0, 21.5])
    payload = pkg.codec("sensor_msgs/msg/BatteryState", "rmw_desert").encode(msg, [0, 4])
    items = cbor2.loads(b"\x9f" + payload + b"\xff")
    assert not any(isinstance(i, cbor2.CBORTag) for i in items)
    assert 3.950000047683716 in items          # the cells are items, one by one


def test_a_remembered_choice_is_the_same_as_a_fresh_one_and_is_not_shared(monkeypatch):
    values = [0.05, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.05]
    fresh = rt._choose(array.array("d", values).tobytes(), "d", False)
    first, second = rt.number_array(values, "d", False, "x"), rt.number_array(list(values), "d", False, "x")
    assert first == second == fresh == values
    out = [0, 4]
    out += first                       # how generated encoders use it: copied, never mutated
    assert rt.number_array(values, "d", False, "x") == values


# Values at the edges of the quick test for normal halves (rt._normal_halves: |x| in
# [2**-13, 2**15), no mantissa bit below half's 10) and beyond them: half's smallest normal
# and subnormals, its largest values, float32's subnormals, zeros, infinities, NaNs.
EDGES = [2.0 ** -13, -2.0 ** -13, 2.0 ** -14, 2.0 ** -24, 2.0 ** -20, 3 * 2.0 ** -24, 2.0 ** -25,
         32752.0, -32752.0, 32768.0, 65504.0, 65520.0, 32767.0, 1.0 + 2.0 ** -10, 1.0 + 2.0 ** -11,
         1e-45, 0.0, -0.0, math.inf, -math.inf, math.nan, 100.0, -0.5, 3.0e38, -3.0e38]


def halves_checked_only(values) -> list:
    """number_array's choice when every float32 array goes through the checked conversion."""
    with mock.patch.object(rt, "_normal_halves", lambda raw: False):
        return rt.number_array(values, "f", True, "x")


@st.composite
def long_lists(draw, elements, min_size: int, max_size: int) -> list:
    """`min_size`..`max_size` values, each one of a pool of at most 16 drawn from `elements`,
    placed by a drawn seed: what decides the arrays' choices is which values occur, and an
    example of hundreds of values then costs Hypothesis a few draws, not hundreds."""
    pool = draw(st.lists(elements, min_size=1, max_size=16))
    rng = random.Random(draw(st.integers(0, 2 ** 32 - 1)))
    return [rng.choice(pool) for _ in range(draw(st.integers(min_size, max_size)))]


@settings(max_examples=300, deadline=None)
@given(values=long_lists(st.one_of(st.sampled_from(EDGES), st.floats(width=16, allow_nan=False),
                                   st.floats(width=32)), rt.NUMPY_FROM + 1, 200))
def test_the_quick_half_test_gives_the_bytes_of_the_checked_conversion(values):
    quick = rt.number_array(values, "f", True, "x")
    assert pack_items(quick) == pack_items(halves_checked_only(values))


@pytest.mark.parametrize("edge", EDGES, ids=repr)
def test_an_edge_value_among_halves_gives_the_checked_bytes_and_comes_back(pkg, edge):
    values = [float(100 + k % 50) for k in range(rt.NUMPY_FROM + 11)]
    values[7] = edge
    quick = rt.number_array(values, "f", True, "x")
    assert pack_items(quick) == pack_items(halves_checked_only(values))
    with mock.patch.object(rt, "_np", None):              # and the struct conversion agrees
        assert pack_items(rt.number_array(values, "f", True, "x")) == pack_items(quick)
    msg = scan([1.0] * 3, values)
    back, _ = pkg.codec("sensor_msgs/msg/LaserScan").decode(pkg.codec("sensor_msgs/msg/LaserScan").encode(msg, [0, 4]), (0, 4))
    assert back.intensities.tobytes() == array.array("f", values).tobytes()


def test_the_quick_half_test_takes_only_normal_halves():
    normal = array.array("f", [2.0 ** -13, 1.5, -100.0, 32752.0, 1.0 + 2.0 ** -10]).tobytes()
    assert rt._normal_halves(normal)
    for other in (0.0, -0.0, 2.0 ** -14, 2.0 ** -24, 32768.0, 65504.0, math.inf, math.nan, 1.0 + 2.0 ** -11):
        assert not rt._normal_halves(array.array("f", [1.5, other]).tobytes()), other


F32 = st.one_of(st.sampled_from(EDGES), st.floats(width=16, allow_nan=False), st.floats(width=32))


@settings(max_examples=300, deadline=None)
@given(values=st.one_of(st.lists(F32, max_size=40), long_lists(F32, 129, 300),
                        long_lists(st.floats(width=16, allow_nan=False), 129, 300)),
       counted=st.booleans(), holder=st.sampled_from(["array", "list"]))
def test_float32_array_chooses_as_number_array_does(values, counted, holder):
    value = array.array("f", values) if holder == "array" else values
    assert pack_items(rt.float32_array(value, counted, "x")) == pack_items(rt.number_array(value, "f", counted, "x"))


@pytest.mark.parametrize("fill", [0.0, 1.0 + 2.0 ** -11, math.nan, 1e30, 2.0 ** -24])
def test_float32_array_of_a_long_sequence_matches_number_array_past_its_quick_tests(fill):
    """Arrays the quick tests do not decide (zeros, NaN, values needing single or double
    items, subnormal halves) take number_array's own steps: the same bytes."""
    for k in (rt.CHOICE_CACHE_BYTES // 4 + 1, 300):
        value = array.array("f", [fill] * k)
        value[5] = 3.0
        assert pack_items(rt.float32_array(value, True, "x")) == pack_items(rt.number_array(value, "f", True, "x"))


@pytest.mark.parametrize("count", [1, 5, 200])
def test_nans_with_payload_bits_in_the_lowest_byte_are_counted_as_short_items(count):
    """A NaN whose lowest byte is not 0 (a payload) is still a short item (F9 7E 00): the
    quick look at the top bytes must find it. Many of them make the items the smaller."""
    for fill in (0.1, 100.0):
        value = array.array("f", [fill] * 300)
        raw = bytearray(value.tobytes())
        for k in range(count):
            raw[4 * k:4 * k + 4] = bytes((0x5A, 0x00, 0xC0, 0xFF if k % 2 else 0x7F))
        value = array.array("f", bytes(raw))
        assert math.isnan(value[0]) and value.tobytes()[0] == 0x5A
        quick = rt.float32_array(value, True, "x")
        assert pack_items(quick) == pack_items(rt.number_array(value, "f", True, "x"))
        assert len(pack_items(quick)) <= len(pack_items([300, *value.tolist()]))
