"""Moved: the type support build is `uwgen.typesupport` (cache outside the source tree,
any interface package, `uwgen ros-interfaces`). These names stay for the demo's callers."""
from uwgen.typesupport import BuildError, InterfaceEnv, ensure_interfaces  # noqa: F401
