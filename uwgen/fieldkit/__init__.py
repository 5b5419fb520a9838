"""The field kit: what an operator reads a link by, during a dive and after it.

- `msgdef`: ROS 2 message definitions (ros2msg text) of rclpy classes, for MCAP schemas;
- `writer`: a rotating MCAP file written from a thread of its own (bridge recordings);
- `reader`: recordings read back, a file cut short up to its last complete chunk;
- `summary`: one or both sides' recordings matched across the link, as the demo's table;
- `plots`: delivery, latency, air use and losses as PNG.

Nothing here imports the bridge: `uwgen log` reads recordings without ROS running.
"""
