"""What a generated package is made of: the plan that `generator.plan_package` decides and
`render.render_package` lays out (modules, their plain classes, functions and imports, the
codec table's entries).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from uwgen.codegen.emit_common import Function, module_alias
from uwgen.manifest.model import Manifest


@dataclass
class PlainField:
    name: str
    param_default: str     # default in the __init__ signature
    init_expr: str         # what __init__ assigns


@dataclass
class PlainClass:
    name: str
    full_name: str
    fields: list[PlainField]
    constants: list[tuple[str, str]]
    me: str = "self"       # __init__'s instance parameter: '_self' when a field is named self


@dataclass
class ServiceHolder:
    name: str
    full_name: str


@dataclass
class ActionHolder:
    name: str
    full_name: str


@dataclass
class ModulePlan:
    package: str                                              # ROS package
    namespace: str                                            # msg, srv or action
    imports: list[tuple[str, str, str]] = field(default_factory=list)  # (package, namespace, alias) used
    classes: list[PlainClass] = field(default_factory=list)
    services: list[ServiceHolder] = field(default_factory=list)
    actions: list[ActionHolder] = field(default_factory=list)
    functions: list[Function] = field(default_factory=list)
    constants: list[str] = field(default_factory=list)
    bits_imports: list[str] = field(default_factory=list)    # uwgen.runtime.wire.bits helpers used

    @property
    def name(self) -> str:
        return f"{self.package}.{self.namespace}"

    def need_import(self, module: str) -> None:
        """Import generated module `module` (by its alias) unless it is this one."""
        entry = (*module.split("."), module_alias(module))
        if module != self.name and entry not in self.imports:
            self.imports.append(entry)


@dataclass
class CodecEntry:
    type_name: str
    profile: str
    key: str
    module: str       # alias of its module: '_geometry_msgs_msg'
    enc: str
    dec: str
    variant: str = ""  # '' or the name of a manifest field-encoding variant ('t4', 'q21', 'r21')
    enc_slots: str = ""  # the encoder that reads rclpy's slots (emit_common.slots_name), if any


@dataclass
class PackagePlan:
    package: str
    sources: list[tuple[str, str]]          # (label, sha256 prefix)
    manifest_label: str | None
    manifest: Manifest | None
    modules: list[ModulePlan]
    codecs: list[CodecEntry]
    ros_imports: list[tuple[str, str, str]]  # (class key, module, class name)
    ros_layouts: list[tuple[str, str]]       # (class key, repr of rosidl_layout.ros_layout)
    plain_keys: list[tuple[str, str, str]]   # (class key, generated module, class name)
    skipped: list[str] = field(default_factory=list)   # types a profile can never carry (bulk builds)
    fingerprints: dict[tuple[str, int], bytes] = field(default_factory=dict)  # ('topic'|'service', id) -> fp
    schema_digest: bytes | None = None                # of every fingerprint (None without a manifest)
    seal_fingerprints: dict[int, bytes] = field(default_factory=dict)   # fingerprint.seal_fingerprints
    # Local interface packages used: (package, folder label, digest of its .msg/.srv files);
    # bridges activate the rclpy type support built from exactly these (uwgen.typesupport).
    ros_interfaces: list[tuple[str, str, str]] = field(default_factory=list)
    source_paths: list[tuple[Path, bool]] = field(default_factory=list)   # (definition file, local)
    built_from: dict | None = None     # uwgen.buildinfo record, set by `uwgen build`
