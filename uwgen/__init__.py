"""uwgen: compact CBOR codecs and bridge nodes that carry ROS 2 over DESERT acoustic links.

Packages, by job:
  uwgen.idl        parse ROS 2 .msg/.srv definitions (folders and installed packages)
  uwgen.manifest   read and validate the network manifest (YAML)
  uwgen.codegen    codec IR, jinja2 generator, `generated/` writer and checker
  uwgen.runtime    what generated code shares: CBOR primitives, framing, fragments,
                   the DESERT connection, link scheduler, clocks
  uwgen.emulator   a faithful emulator of DESERT's application socket and channel
  uwgen.bridge     the rclpy side of generated bridge nodes
  uwgen.interop    rmw_desert compatibility: id table JSON, discovery beacons
  uwgen.commands   one module per `uwgen` sub-command
"""

__version__ = "0.1.0"
