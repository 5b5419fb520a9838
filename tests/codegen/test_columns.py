"""Arrays of numeric structs by columns (wire-format.md section 4.2): the page's worked bytes
and sizes, round trips of real rclpy messages, never larger than the items, errors with the
member's path, damaged bodies refused with the decode error only, the fingerprint changed."""
from __future__ import annotations

import dataclasses
import math
import re
import struct
from pathlib import Path

import pytest
from geometry_msgs.msg import Point32, Polygon, PolygonStamped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import JoyFeedback, JoyFeedbackArray

from uwgen.codegen import generate
from uwgen.codegen.encodings import ColumnArray, MessageArray
from uwgen.codegen.fingerprint import topic_fingerprint
from uwgen.codegen.ir import IRBuilder
from uwgen.idl.loader import InterfaceLibrary
from uwgen.runtime.wire.codec import DecodeError, EncodeError, head_size, pack_items

from .rosvalues import normalize
from .test_properties import message_strategy

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"
ROS_TYPES = ["geometry_msgs/msg/PolygonStamped", "sensor_msgs/msg/JoyFeedbackArray",
             "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint", "visualization_msgs/msg/Marker",
             "shape_msgs/msg/Mesh", "geometry_msgs/msg/PoseArray"]
LOCAL = {  # fixed and bounded arrays, every integer width, floats of both widths
    "col_msgs/msg/Cell.msg": "int8 a\nuint16 b\nint32 c\nuint64 d\nfloat64 e\nInner f\n",
    "col_msgs/msg/Inner.msg": "float32 g\nint64 h\n",
    "col_msgs/msg/Grid.msg": "Cell[3] fixed\nCell[<=4] bounded\nstring name\n",
}
EXAMPLES = {
    "polygon": Polygon(points=[Point32(x=0.1, y=0.5, z=0.0), Point32(x=3.95, y=1.5, z=0.0)]),
    "items": Polygon(points=[Point32(x=0.1, y=200000.0, z=0.0), Point32(x=3.95, y=1.5, z=0.0),
                             Point32(x=3.95, y=1.5, z=0.0)]),
    "integers": JoyFeedbackArray(array=[JoyFeedback(type=1, id=0, intensity=1.0),
                                        JoyFeedback(type=2, id=1, intensity=0.5)]),
    "empty": Polygon(),
}
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    root = tmp_path_factory.mktemp("columns")
    folder = root / "defs"
    for rel, text in LOCAL.items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_text(text)
    return generate(root, "uwgen_columns", names=ROS_TYPES + ["geometry_msgs/msg/Polygon"], folders=[folder],
                    profiles=("native", "rmw_desert", "packed"))


def doc_rows() -> dict[str, tuple[str, str]]:
    section = DOC.read_text().split("### 4.2", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| ([a-z]+) \| [^|]+ \| `([0-9A-F ]+)` \| ([^|]+) \|$", section, re.M)
    return {name: (payload, sizes.strip()) for name, payload, sizes in rows}


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def members(msg) -> list[tuple[str, list, str]]:
    """(name, values, struct code) of each column of an example."""
    if isinstance(msg, Polygon):
        return [(a, [f32(getattr(p, a)) for p in msg.points], "f") for a in "xyz"]
    return [("type", [e.type for e in msg.array], "B"), ("id", [e.id for e in msg.array], "B"),
            ("intensity", [f32(e.intensity) for e in msg.array], "f")]


def test_every_example_row_of_section_4_2_is_checked():
    assert set(doc_rows()) == set(EXAMPLES)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_section_4_2_worked_bytes_and_sizes(pkg, name):
    msg = EXAMPLES[name]
    type_name = "geometry_msgs/msg/Polygon" if isinstance(msg, Polygon) else "sensor_msgs/msg/JoyFeedbackArray"
    codec = pkg.codec(type_name)
    payload = codec.encode(msg, [0, 4])
    want, stated = doc_rows()[name]
    assert payload.hex(" ").upper() == want
    cols = members(msg)
    n = len(cols[0][1])
    h = head_size
    sizes = {}
    for member, values, code in cols:   # the section's formulas, recomputed
        w = struct.calcsize("<" + code)
        sizes[member] = {"I": len(pack_items(values)), "B": h(w * n) + w * n, "H": h(2 * n) + 2 * n}
    for member, letter, value in re.findall(r"(\w+) ([IBH]) = (\d+)", stated):
        assert sizes[member][letter] == int(value), (member, letter, sizes)
    # and the payload is the count, then each column in the smallest allowed form
    expected = 2 + h(n) + sum(min([s["I"], s["B"]] + ([s["H"]] if halves(v, c) else []))
                              for (_m, v, c), s in zip(cols, sizes.values())) if n else 3
    assert len(payload) == expected
    back, _ = codec.decode(payload, (0, 4))
    assert [m[1] for m in members(back)] == [m[1] for m in cols]


def halves(values: list, code: str) -> bool:
    if code not in "fd":
        return False
    try:
        return all(struct.unpack("<e", struct.pack("<e", v))[0] == v for v in values)
    except (OverflowError, struct.error):
        return False


def items_size(pkg, type_name: str, msg, points: list, header_msg) -> int:
    """The old form's size: the header fields, then the count and every element's items."""
    header = len(pkg.codec(type_name).encode(header_msg, [0, 4])) - 1
    return header + len(pack_items([len(points), *[f32(v) for p in points for v in (p.x, p.y, p.z)]]))


@given(st.lists(st.tuples(st.floats(width=32, allow_nan=False), st.floats(width=32, allow_nan=False),
                          st.sampled_from([0.0, 1.5, -2.0, 1e-3, 3.3e5])), max_size=60))
@SETTINGS
def test_columns_are_never_larger_than_the_items(pkg, points):
    pts = [Point32(x=x, y=y, z=z) for x, y, z in points]
    msg = Polygon(points=pts)
    assert len(pkg.codec("geometry_msgs/msg/Polygon").encode(msg, [0, 4])) <= \
        items_size(pkg, "geometry_msgs/msg/Polygon", msg, pts, Polygon())


@pytest.mark.parametrize("type_name", ROS_TYPES)
def test_random_rclpy_messages_round_trip_by_columns(pkg, type_name):
    module, _ns, name = type_name.split("/")
    cls = getattr(__import__(f"{module}.msg", fromlist=[name]), name)
    codec = pkg.codec(type_name)

    @SETTINGS
    @given(message_strategy(cls))
    def check(msg):
        payload = codec.encode(msg, [0, 7])
        for ros in (True, False):
            back, _ = codec.decode(payload, (0, 7), ros=ros)
            if ros:
                assert normalize(back) == normalize(msg)

    check()


def builder() -> tuple[InterfaceLibrary, IRBuilder]:
    lib = InterfaceLibrary([], installed=True)
    return lib, IRBuilder(lib.get)


def test_the_build_sends_these_arrays_by_columns_in_native_only(pkg):
    lib, b = builder()
    for profile, kind in (("native", ColumnArray), ("rmw_desert", MessageArray), ("packed", MessageArray)):
        ct = b.codec(lib.get("geometry_msgs/msg/Polygon"), profile)
        assert type(ct.root.children[0].encoding) is kind, profile
    # in the other profiles the same message still travels as items
    msg = EXAMPLES["polygon"]
    rmw = pkg.codec("geometry_msgs/msg/Polygon", "rmw_desert").encode(msg, [0, 4])
    assert len(rmw) == 2 + 1 + len(pack_items([f32(v) for p in msg.points for v in (p.x, p.y, p.z)]))


def test_fixed_and_bounded_arrays_of_every_width_round_trip(pkg):
    codec = pkg.codec("col_msgs/msg/Grid")
    Cell, Inner, Grid = (codec.plain_class() if n == "Grid" else pkg.codec(f"col_msgs/msg/{n}").plain_class()
                         for n in ("Cell", "Inner", "Grid"))

    def cell(k: int):
        return Cell(a=-128 + k, b=65535 - k, c=-2 ** 31 + k, d=2 ** 64 - 1 - k, e=1e300 / (k + 1),
                    f=Inner(g=0.5 * k, h=-2 ** 63 + k))
    msg = Grid(fixed=[cell(k) for k in range(3)], bounded=[cell(k) for k in range(4)], name="g")
    payload = codec.encode(msg, [0, 4])
    back, _ = codec.decode(payload, (0, 4), ros=False)
    assert back == msg
    short = Grid(fixed=[cell(0)], bounded=[], name="g")
    with pytest.raises(EncodeError, match=r"^fixed: 1 elements in a fixed array of 3"):
        codec.encode(short, [0, 4])
    over = Grid(fixed=[cell(k) for k in range(3)], bounded=[cell(k) for k in range(5)], name="g")
    with pytest.raises(EncodeError, match=r"^bounded: 5 elements, over the bound of 4"):
        codec.encode(over, [0, 4])


def test_a_value_that_does_not_fit_names_the_element_and_member(pkg):
    codec = pkg.codec("geometry_msgs/msg/PolygonStamped")
    msg = PolygonStamped()
    msg.polygon.points = [Point32(x=1.0), Point32(x=2.0), Point32(x=3.0)]
    msg.polygon.points[1].y = 1e39         # rclpy takes it; float32 cannot carry it
    with pytest.raises(EncodeError, match=r"^polygon\.points\[1\]\.y: "):
        codec.encode(msg, [0, 4])
    msg.polygon.points[1] = "not a point"
    with pytest.raises(EncodeError, match=r"^polygon\.points\[1\]"):
        codec.encode(msg, [0, 4])
    grid = pkg.codec("col_msgs/msg/Grid")
    Cell, Inner = (pkg.codec(f"col_msgs/msg/{n}").plain_class() for n in ("Cell", "Inner"))
    bad = grid.plain_class()(fixed=[Cell(), Cell(b=70000), Cell()], name="g")
    with pytest.raises(EncodeError, match=r"^fixed\[1\]\.b: 70000 does not fit uint16"):
        grid.encode(bad, [0, 4])
    bad = grid.plain_class()(fixed=[Cell(), Cell(), Cell(f=Inner(g="x"))], name="g")
    with pytest.raises(EncodeError, match=r"^fixed\[2\]\.f\.g"):
        grid.encode(bad, [0, 4])


@pytest.mark.parametrize("payload, path", [
    ("00 04 02 47 CD CC CC 3D CD CC 7C", r"points\[\]\.x: a column of 7 bytes for 2 values of 4 or 2"),
    ("00 04 02 48 CD CC CC 3D CD CC 7C 40 44 00 38 00 3E", r"points\[\]\.z: payload ended"),
    ("00 04 02 48 CD CC CC 3D CD CC 7C 40 F9 38 00", r"points\[\]\.y: payload ended"),
    ("00 04 02 48 CD CC CC 3D CD CC 7C 40 01 02 44 00 00 00 00", r"points\[0\]\.y: expected a float"),
    ("00 04 02 48 CD CC CC 3D CD CC 7C 40 44 00 38 00 3E 44 00 00 00 00 00", r"item left over|left over"),
    ("00 04 19 FF FF 40", r"points\[\]\.x: a column of 0 bytes for 65535 values"),
])
def test_bad_columns_are_refused_with_the_member_path(pkg, payload, path):
    with pytest.raises(DecodeError, match=path):
        pkg.codec("geometry_msgs/msg/Polygon").decode(bytes.fromhex(payload), (0, 4))


def test_an_integer_column_out_of_range_is_refused(pkg):
    # JoyFeedback's type is uint8: an item 256 in its column
    with pytest.raises(DecodeError, match=r"array\[1\]\.type: expected an uint8, got 256"):
        pkg.codec("sensor_msgs/msg/JoyFeedbackArray").decode(
            bytes.fromhex("00 04 02 01 19 01 00 00 01 44 00 3C 00 38"), (0, 4))


@pytest.mark.parametrize("type_name", ["geometry_msgs/msg/PolygonStamped", "col_msgs/msg/Grid"])
def test_truncated_and_damaged_bodies_raise_only_the_decode_error(pkg, type_name):
    codec = pkg.codec(type_name)
    if type_name == "col_msgs/msg/Grid":
        Cell, Inner = (pkg.codec(f"col_msgs/msg/{n}").plain_class() for n in ("Cell", "Inner"))
        msg = codec.plain_class()(fixed=[Cell(e=0.1 * k, f=Inner(g=2.5)) for k in range(3)],
                                  bounded=[Cell(a=3)], name="g")
    else:
        msg = PolygonStamped()
        msg.polygon.points = [Point32(x=0.1 * k, y=1.5, z=0.0) for k in range(5)]
    payload = codec.encode(msg, [0, 7])
    damaged = [payload[:k] for k in range(len(payload))]
    damaged += [payload[:k] + bytes([payload[k] ^ 0xFF]) + payload[k + 1:] for k in range(len(payload))]
    refused = 0
    for data in damaged:
        try:
            codec.decode(data, (0, 7), ros=False)
        except DecodeError:
            refused += 1
    assert refused >= len(payload) - 2     # every truncation but the whole payload is refused


@given(st.binary(max_size=80).map(lambda b: b"\x00\x07" + b))
@SETTINGS
def test_random_bodies_raise_only_the_decode_error(pkg, data):
    for type_name in ("geometry_msgs/msg/PolygonStamped", "col_msgs/msg/Grid"):
        try:
            pkg.codec(type_name).decode(data, (0, 7), ros=False)
        except DecodeError:
            pass


def test_the_fingerprint_hashes_the_column_form():
    lib, b = builder()
    ct = b.codec(lib.get("geometry_msgs/msg/Polygon"), "native")
    uses = {k: b.by_key(k, "native") for k in ct.uses}
    node = ct.root.children[0]
    enc = node.encoding
    as_items = MessageArray(enc.array, enc.size, enc.type_key, enc.elem_min_items, enc.elem_fixed_items,
                            enc.elem_min_bytes)
    items_ct = dataclasses.replace(ct, root=dataclasses.replace(ct.root, children=[
        dataclasses.replace(node, encoding=as_items)]))
    by_columns = topic_fingerprint(4, "native", ct.full_name, ct, uses)
    by_items = topic_fingerprint(4, "native", ct.full_name, items_ct, uses)
    assert by_columns != by_items


def test_a_column_of_one_value_throughout_round_trips_in_its_smallest_form(pkg):
    codec = pkg.codec("geometry_msgs/msg/Polygon")
    msg = Polygon(points=[Point32(x=1.5, y=0.1, z=-0.0) for _ in range(5)])
    payload = codec.encode(msg, [0, 4])
    # x: five halves 3E 00; y: no half, five float32; z: -0.0 is a half (00 80), not all zero bytes
    assert payload.hex(" ").upper() == ("00 04 05 4A" + " 00 3E" * 5 + " 54" + " CD CC CC 3D" * 5
                                        + " 4A" + " 00 80" * 5)
    back, _ = codec.decode(payload, (0, 4))
    assert [(p.x, p.y, math.copysign(1, p.z)) for p in back.points] == [(1.5, f32(0.1), -1.0)] * 5
