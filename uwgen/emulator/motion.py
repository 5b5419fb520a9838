"""Where a node is at a given time: fixed, following waypoints, or driven by a live pose.

- `waypoints`: a list of (t, x, y, z) points (seconds since the emulator started,
  metres); between two points the node moves in a straight line at constant speed,
  before the first and after the last it stays put.
- `PoseFeed`: the node follows a ROS topic (a vehicle's own pose or odometry); each
  message's position is multiplied by `scale` and `offset` is added, so a simulator
  working in a few metres can stand for kilometres of sea. The ROS side is
  `uwgen.emulator.ros_pose`; the core only sees `set_position(node, t, xyz)`.

Propagation delay and SNR of a packet use the distance between sender and receiver at
the moment it is sent (an AUV moves about 2 m/s, sound 1500 m/s: the distance changes by
well under a metre while a packet travels).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

Position = tuple[float, float, float]


@dataclass(frozen=True)
class PoseFeed:
    """Drive a node's position from a ROS topic (see module doc and uwgen.emulator.ros_pose).

    type is the ROS type (`pkg/msg/Name`): geometry_msgs Pose, PoseStamped,
    PoseWithCovarianceStamped, nav_msgs Odometry, turtlesim Pose, or any message with a
    position (x, y[, z]) found at `.pose.pose.position`, `.pose.position`, `.position` or
    on itself.
    """

    topic: str
    type: str = "nav_msgs/msg/Odometry"
    scale: float = 1.0
    offset: Position = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not isinstance(self.topic, str) or not self.topic.startswith("/"):
            raise ValueError(f"pose topic must be an absolute ROS name, got {self.topic!r}")
        if not isinstance(self.type, str) or self.type.count("/") != 2:
            raise ValueError(f"pose type must look like pkg/msg/Name, got {self.type!r}")
        if not _finite(self.scale) or self.scale <= 0:
            raise ValueError(f"pose scale must be a positive number, got {self.scale!r}")
        if len(self.offset) != 3 or not all(_finite(c) for c in self.offset):
            raise ValueError(f"pose offset must be three numbers, got {self.offset!r}")

    def to_position(self, xyz: tuple[float, float, float]) -> Position:
        return tuple(self.scale * c + o for c, o in zip(xyz, self.offset))  # type: ignore[return-value]


def position_from_msg(msg) -> tuple[float, float, float]:
    """The (x, y, z) of a pose-like ROS message (see PoseFeed); z is 0 when it has none."""
    for path in (("pose", "pose", "position"), ("pose", "position"), ("position",), ()):
        obj = msg
        try:
            for attr in path:
                obj = getattr(obj, attr)
            x, y = float(obj.x), float(obj.y)
        except (AttributeError, TypeError, ValueError):
            continue
        z = float(getattr(obj, "z", 0.0) or 0.0)
        return x, y, z
    raise ValueError(f"{type(msg).__name__} has no position (x, y[, z])")


class Track:
    """Piecewise-linear motion through (t, x, y, z) waypoints (times strictly increasing)."""

    __slots__ = ("_times", "_points")

    def __init__(self, waypoints):
        self._times = [float(w[0]) for w in waypoints]
        self._points = [tuple(float(c) for c in w[1:]) for w in waypoints]

    def at(self, t: float) -> Position:
        times = self._times
        if t <= times[0]:
            return self._points[0]  # type: ignore[return-value]
        if t >= times[-1]:
            return self._points[-1]  # type: ignore[return-value]
        i = bisect.bisect_right(times, t)
        t0, t1 = times[i - 1], times[i]
        p0, p1 = self._points[i - 1], self._points[i]
        f = (t - t0) / (t1 - t0)
        return tuple(a + (b - a) * f for a, b in zip(p0, p1))  # type: ignore[return-value]


def check_waypoints(waypoints) -> str | None:
    """None if `waypoints` is a valid track, else what is wrong with it."""
    if not isinstance(waypoints, (list, tuple)) or not waypoints:
        return "waypoints must be a non-empty list of [t, x, y, z]"
    last = -math.inf
    for i, w in enumerate(waypoints):
        if not isinstance(w, (list, tuple)) or len(w) != 4 or not all(_finite(c) for c in w):
            return f"waypoint {i} must be four numbers [t, x, y, z], got {w!r}"
        if w[0] < 0:
            return f"waypoint {i}: time must be >= 0, got {w[0]!r}"
        if w[0] <= last:
            return f"waypoint {i}: times must increase ({w[0]!r} after {last!r})"
        last = w[0]
    return None


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


class Geometry:
    """Where every node of a scenario is, and what a packet between two of them meets:
    (propagation delay, mean received power, mean SNR in dB) at the moment it is sent.
    Pairs of fixed nodes are computed once; a pair with a moving node at each packet."""

    def __init__(self, scenario, start: float = 0.0):
        self.scenario = scenario
        snr = scenario.snr
        self.noise_db = snr.noise_db() if snr else 0.0
        self._fixed = {spec.name: spec.position for spec in scenario.nodes}
        self._tracks = {spec.name: Track(spec.waypoints) for spec in scenario.nodes
                        if spec.waypoints}
        self._live: dict[str, Position] = {}
        self._moving = {spec.name for spec in scenario.nodes if scenario.moves(spec.name)}
        names = scenario.names()
        self._static = {(a, b): self._compute(a, b, start) for a in names for b in names
                        if a != b and a not in self._moving and b not in self._moving}

    def set_position(self, node: str, position: Position) -> None:
        """`node` is at `position` from now on (a live pose overrides waypoints)."""
        x, y, z = (float(c) for c in position)
        if not all(math.isfinite(c) for c in (x, y, z)):
            raise ValueError(f"position of {node} must be finite, got {position!r}")
        self._live[node] = (x, y, z)
        if node not in self._moving:
            self._moving.add(node)
            self._static = {k: v for k, v in self._static.items() if node not in k}

    def position(self, node: str, t: float) -> Position:
        if node in self._live:
            return self._live[node]
        track = self._tracks.get(node)
        return track.at(t) if track is not None else self._fixed[node]

    def link(self, a: str, b: str, t: float) -> tuple[float, float, float]:
        """(propagation delay s, mean received power (linear, 1.0 without SNR model), mean SNR
        dB (inf without)) of a packet a sends to b at time t."""
        cached = self._static.get((a, b))
        return cached if cached is not None else self._compute(a, b, t)

    def _compute(self, a: str, b: str, t: float) -> tuple[float, float, float]:
        d = math.dist(self.position(a, t), self.position(b, t))
        delay = d / self.scenario.sound_speed
        snr = self.scenario.snr
        if snr is None:
            return delay, 1.0, math.inf
        received = snr.received_db(d)
        return delay, 10 ** (received / 10), received - self.noise_db
