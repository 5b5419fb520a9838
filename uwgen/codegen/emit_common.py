"""What the lowerings of codec IR to Python share (uwgen.codegen.emit, emit_decode and
emit_packed): the module-level constants a module's functions share, the function record the
templates lay out, names, field access, and the small lowerings of encodings that are not on
the wire or sent as an index.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from uwgen.codegen.encodings import Absent, Enumerated, Quantized, Static, TimeOfDay
from uwgen.codegen.ir import Node

F32_MAX = "3.4028234663852886e+38"


@dataclass
class Constants:
    """Module-level constants the functions of one module share (structs, name tuples)."""
    lines: list[str] = field(default_factory=list)
    _names: dict[str, str] = field(default_factory=dict)

    def struct(self, fmt: str) -> str:
        return self._add(f"_struct.Struct({fmt!r})", "_S")

    def names(self, names: tuple[str, ...]) -> str:
        return self._add(repr(names), "_N")

    def getters(self, paths: tuple[str, ...], slots: bool) -> str:
        """`operator.attrgetter`s of dotted paths in an element ('linear.x'); with `slots`,
        of rclpy's slots behind them ('_linear._x')."""
        if slots:
            paths = tuple(".".join("_" + part for part in path.split(".")) for path in paths)
        return self._add("(" + "".join(f"_attrgetter({path!r}), " for path in paths) + ")", "_G")

    def values(self, values: tuple) -> str:
        """An enum's values, by index."""
        return self._add(repr(tuple(values)), "_V")

    def table(self, values: tuple) -> str:
        """An enum's value -> index table."""
        return self._add(repr({v: k for k, v in enumerate(values)}), "_E")

    def _add(self, expr: str, prefix: str) -> str:
        name = self._names.get(expr)
        if name is None:
            name = f"{prefix}{len(self._names)}"
            self._names[expr] = name
            self.lines.append(f"{name} = {expr}")
        return name


@dataclass
class Function:
    name: str
    args: str
    doc: str
    body: list[str]


def module_alias(module: str) -> str:
    """How one generated module imports another: 'geometry_msgs.msg' -> '_geometry_msgs_msg'."""
    return "_" + module.replace(".", "_")


def func_name(kind: str, ct_key_name: str, suffix: str) -> str:
    return f"{kind}{suffix}_{ct_key_name}"


def slots_name(encoder: str) -> str:
    """The name of the encoder that reads rclpy's slots, beside `encoder`."""
    return f"{encoder}_slots"


def field_access(root: Node, body: list[str], slots: bool = False) -> Callable[[Node], str]:
    """Name each nested message of `root` once (`m1 = m.linear`, appended to `body`) and
    return how a leaf is read: `access(leaf) -> 'm1.x'`; with `slots`, rclpy's slot behind
    each field's property is read instead (`m1._x`)."""
    var_of = {"": "m"}
    prefix = "_" if slots else ""

    def access(node: Node) -> str:
        parent = node.path.rsplit(".", 1)[0] if "." in node.path else ""
        return f"{var_of[parent]}.{prefix}{node.name}"

    def declare(node: Node) -> None:
        for child in node.children or ():
            if child.children is not None:
                var_of[child.path] = var = f"m{len(var_of)}"
                body.append(f"{var} = {access(child)}")
                declare(child)

    declare(root)
    return access


def index_max(enc) -> int:
    """The largest index an index-sent encoding (quantized, enum, time) may carry."""
    if isinstance(enc, Enumerated):
        return len(enc.values) - 1
    if isinstance(enc, TimeOfDay):
        return enc.count - 1
    return enc.nmax


def not_sent(leaf: Node, enc) -> str | None:
    """The comment an encoder writes for a leaf that is not on the wire (absent, or static:
    both sides know its value), else None: the leaf is sent."""
    if isinstance(enc, Absent):
        return f"# {leaf.path}: not sent ({enc.why})"
    if isinstance(enc, Static):
        return f"# {leaf.path}: not sent (static {enc.value!r})"
    return None


def not_read(leaf: Node, enc, body: list[str], value_of: dict[str, str]) -> bool:
    """For a decoder: whether `leaf` is not on the wire. An absent leaf gets a comment (the
    constructor leaves its default), a static one its value in `value_of`."""
    if isinstance(enc, Absent):
        body.append(f"# {leaf.path}: not on the wire ({enc.why})")
        return True
    if isinstance(enc, Static):
        value_of[leaf.path] = static_value(enc)
        return True
    return False


def static_value(enc: Static) -> str:
    """The expression a decoder fills a static field with (a fresh list each time)."""
    if enc.octets == "byte":
        return f"C.octet_list({bytes(enc.value)!r})"
    if enc.octets is not None:
        return f"C.uint8_list({bytes(enc.value)!r})"
    return repr(enc.value)


def quantize_lines(enc: Quantized, expr: str, p: str) -> list[str]:
    """Statements that set `n` to the index of `expr` on the grid of `enc`: the float
    estimate where it is provably the exact answer, else the exact integer computation."""
    exact = f"_quantize(x, {enc.a}, {enc.b}, {enc.d}, {enc.nmax}, {enc.clamp}, {p})"
    if enc.fast is None:
        return [f"x = {expr}", f"n = {exact}"]
    lo, inv, tol = enc.fast
    tol = 10.0 ** math.ceil(math.log10(tol))      # a round bound above the error bound
    scaled = offset(lo) if inv == 1.0 else f"{offset(lo)} * {inv!r}"
    return [f"x = {expr}",
            f"e = {scaled} if type(x) is float else -1.0",
            f"if 0.0 <= e <= {enc.nmax} and {tol!r} < (e + 0.5) % 1.0 < 1 - {tol!r}: n = int(e + 0.5)",
            f"else: n = {exact}  # outside the grid or near a rounding boundary: exact"]


def offset(lo: float) -> str:
    """`x - lo` as a reader would write it."""
    if lo == 0:
        return "x"
    return f"(x - {lo!r})" if lo > 0 else f"(x + {-lo!r})"
