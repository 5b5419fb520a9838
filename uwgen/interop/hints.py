"""Types of well-known ROS topic and service names, for starting a manifest from an id table.

rmw_desert's `ros_allowed_topics.conf` has names and ids but no types. For a few names
the type is fixed by convention (turtlesim, the ROS 2 demos, common robot drivers); the
import uses these only for names listed here exactly, only when the type is known to
the interface library, and says so in a comment next to each type it took from here.
"""
from __future__ import annotations

KNOWN_TYPES: dict[str, str] = {
    # turtlesim (the thesis' teleoperation test)
    "/turtle1/cmd_vel": "geometry_msgs/msg/Twist",
    "/turtle1/pose": "turtlesim/msg/Pose",
    "/turtle1/color_sensor": "turtlesim/msg/Color",
    "/turtle1/teleport_absolute": "turtlesim/srv/TeleportAbsolute",
    "/turtle1/teleport_relative": "turtlesim/srv/TeleportRelative",
    "/turtle1/set_pen": "turtlesim/srv/SetPen",
    "/spawn": "turtlesim/srv/Spawn",
    "/kill": "turtlesim/srv/Kill",
    "/clear": "std_srvs/srv/Empty",
    "/reset": "std_srvs/srv/Empty",
    # ROS 2 demos
    "/chatter": "std_msgs/msg/String",
    "/add_two_ints": "example_interfaces/srv/AddTwoInts",
    # common robot conventions (REP 105 / REP 145 names)
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/odom": "nav_msgs/msg/Odometry",
    "/imu": "sensor_msgs/msg/Imu",
    "/imu/data": "sensor_msgs/msg/Imu",
    "/battery_state": "sensor_msgs/msg/BatteryState",
    "/joy": "sensor_msgs/msg/Joy",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/fix": "sensor_msgs/msg/NavSatFix",
}
