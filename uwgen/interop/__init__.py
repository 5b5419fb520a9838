"""rmw_desert interoperability: id table JSON and discovery beacons."""
