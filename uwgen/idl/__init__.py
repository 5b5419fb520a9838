"""Parsing ROS 2 interface definitions into uwgen.idl.model objects."""
