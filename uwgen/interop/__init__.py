"""rmw_desert interoperability: id table JSON and discovery beacons (wire-format.md 6, 6.1).

Modules (imported on demand; none of them loads rclpy):

- `beacons`: Beacon, Entity, encode_beacon / decode_beacon (total: Beacon or BeaconError),
  encode_discovery_request, is_discovery_payload, rmw_type_name / ros_type_name,
  derive_gid;
- `graph`: RemoteGraph (beacons heard, by gid) and format_graph for the terminal;
- `discovery`: bridge_beacons(manifest, side), discovery_policies(n), DiscoveryAgent;
- `rmw_config`: export_conf / conf_table (manifest -> ros_allowed_topics.conf),
  parse_conf / read_conf, resolve_types, manifest_from_conf (id table -> manifest YAML);
- `hints`: types of well-known names (turtlesim, /chatter, ...).

How a bridge uses discovery (profile rmw_desert on any of its entries):

    beacons = bridge_beacons(manifest, side)          # refuses over-long names at start
    for key, policy in discovery_policies(len(beacons)).items():
        link.add_channel(key, policy, whole=True)     # keys 1 and 2, never fragmented
    agent = DiscoveryAgent(beacons, send=link.offer, clock=clock)
    agent.start()                                     # request + beacons (and on reconnect:
                                                      # agent.announce(request=True))
    # in on_payload, before the id table lookup:
    if agent.handle(payload): return                  # discovery traffic, taken
    agent.graph.as_dict()                             # for ~/status; agent.stats() counters
    agent.stop()                                      # disconnect beacons, before link.stop()
"""
