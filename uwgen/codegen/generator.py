"""Plan a generated package: which types, in which profiles, in which modules.

    plan = plan_package(lib, names, manifest, package)   # which types, in which profiles
    files = render.render_package(plan)                  # {relative path: text}
    render.write_package(files, out_dir) / render.stale_files(files, out_dir)

One module per ROS package (`geometry_msgs.py`) holds that package's plain classes
(uwgen.codegen.plain_classes) and the encoder/decoder of each of its types in each profile
used; `_classes.py` holds the class namespaces decoders build from; `__init__.py` holds the
codec table; one `bridge_<side>.py` per manifest side starts that side's bridge. The plan's
shape is uwgen.codegen.package_plan; uwgen.codegen.render lays it out through the
templates. Output depends only on the inputs: the same definitions and manifest give the
same bytes.
"""
from __future__ import annotations

import hashlib
import keyword
from pathlib import Path

from uwgen.errors import Collector
from uwgen.codegen.emit import Lowering
from uwgen.codegen.emit_common import Constants, module_alias
from uwgen.codegen.emit_packed import PackedLowering
from uwgen.codegen.encodings import type_key
from uwgen.codegen.fingerprint import manifest_fingerprints, package_digest, seal_fingerprints
from uwgen.codegen.ir import CodecType, IRBuilder, ProfileError, check_profile_limits, variant_name
from uwgen.codegen.package_plan import ActionHolder, CodecEntry, ModulePlan, PackagePlan, ServiceHolder
from uwgen.codegen.plain_classes import plain_class
from uwgen.codegen.rosidl_layout import ros_layout
from uwgen.idl.loader import InterfaceLibrary, parts_of
from uwgen.idl.model import ActionDef, DefinitionError, MessageDef, ServiceDef, SourceRef
from uwgen.manifest.model import NATIVE, PACKED, Manifest


def source_label(path: Path | None, lib: InterfaceLibrary) -> str:
    """A machine-independent name for a definition file: relative to its folder's parent
    for given folders, `<pkg>/<msg|srv>/<file>` under `share/` for installed ones."""
    if path is None:
        return "<string>"
    path = Path(path)
    for folder in lib.folders:
        try:
            return str(Path(folder.name) / path.resolve().relative_to(folder.resolve()))
        except ValueError:
            continue
    return "share/" + "/".join(path.parts[-3:])


def _digest(path: Path | None) -> str:
    if path is None:
        return "-"
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]


# --- planning ------------------------------------------------------------------------

def plan_build(folders: list[Path], names: list[str] = (), manifest_path: Path | None = None,
               package: str | None = None, profiles: tuple[str, ...] = (NATIVE,),
               installed: bool = True, all_installed: bool = False,
               manifest_label: str | None = None) -> PackagePlan:
    """What `uwgen build` and `uwgen.codegen.generate()` share: read the interfaces and the
    manifest, choose the names, plan the package. `names` add interfaces to the folders'
    own; `all_installed` builds every interface known. The package name defaults to the
    manifest's, then to uwgen_<first folder's name>."""
    from uwgen.linkfloor import check_read_lengths
    from uwgen.manifest.loader import load_manifest   # yaml, only when a build runs

    from uwgen.manifest.loader import ManifestError

    lib = InterfaceLibrary(folders, installed=installed)
    # Every broken definition of the folders and every broken manifest entry is reported
    # (up to uwgen.errors.MAX_ERRORS), not only the first.
    errors = Collector()
    for name in lib.local_names():
        with errors.attempt(DefinitionError):
            lib.get(name)
    manifest = None
    if manifest_path:
        with errors.attempt(ManifestError, DefinitionError):
            manifest = load_manifest(Path(manifest_path), lib)
        if manifest is not None:
            with errors.attempt(ManifestError):
                check_read_lengths(manifest)     # the floor of this network's packets
    errors.raise_if_any()
    wanted = lib.all_names() if all_installed else [*lib.local_names(), *names]
    wanted = sorted({lib.normalize(n) or n for n in wanted})
    package = package or (manifest.package if manifest else None) \
        or f"uwgen_{Path(folders[0]).resolve().name if folders else 'interfaces'}"
    label = manifest_label or (str(manifest_path) if manifest_path else None)
    return plan_package(lib, wanted, manifest, package, tuple(profiles), label)


def plan_package(lib: InterfaceLibrary, names: list[str], manifest: Manifest | None,
                 package: str, profiles: tuple[str, ...] = (NATIVE,),
                 manifest_label: str | None = None) -> PackagePlan:
    """Decide what to generate: `names` in each of `profiles`, plus the manifest's topics,
    services and actions in their own profiles, and every type those use."""
    if manifest is not None and manifest_label is None:   # the package names its manifest
        manifest_label = Path(manifest.source).name if manifest.source else "<manifest>"
    builder = IRBuilder(lambda n: _as_message(lib.get(n)))
    # (type, profile, header items, required, field encodings, variant)
    wanted: list[tuple[MessageDef, str, int, bool, tuple, str]] = []
    for name in names:
        definition = lib.get(name)
        for profile in profiles:
            for msg in parts_of(definition):
                wanted.append((msg, profile, header_len(msg), False, (), ""))
    if manifest is not None:
        for topic in manifest.topics:
            wanted.append((topic.type, topic.profile, 2, True, topic.fields, variant_name("t", topic.id, topic.fields)))
        for service in manifest.services:
            wanted += [(service.type.request, service.profile, 3, True, service.request_fields,
                        variant_name("q", service.id, service.request_fields)),
                       (service.type.response, service.profile, 3, True, service.response_fields,
                        variant_name("r", service.id, service.response_fields))]
        for action in manifest.actions:
            wanted += [(msg, action.profile, header_len(msg), True, (), "") for msg in action.type.parts]

    codecs: dict[tuple[str, str, str], CodecType] = {}
    skipped: list[str] = []
    errors = Collector()
    for msg, profile, header_items, required, fields, variant in wanted:
        try:
            check_profile_limits(builder.codec(msg, profile), header_items)
        except ProfileError as exc:
            if required:  # the manifest asks for it: refuse the build
                errors.add(exc)
            else:
                skipped.append(str(exc))  # a bulk build: leave out what this profile can never carry
            continue
        for ct in builder.codecs_for(msg, profile):
            if variant and ct.full_name == msg.full_name:
                continue   # the entry uses its own variant; only what that uses is needed
            codecs.setdefault((ct.full_name, profile, ""), ct)
        if variant:
            codecs[(msg.full_name, profile, variant)] = builder.codec(msg, profile, fields, variant)
    errors.raise_if_any()

    definitions: dict[str, MessageDef] = {}
    for (full_name, _profile, _variant) in codecs:
        definitions[full_name] = _python_safe(_as_message(lib.get(full_name)))
    services: dict[str, ServiceDef] = {}
    actions: dict[str, ActionDef] = {}
    for name in names:
        d = lib.get(name)
        if isinstance(d, ServiceDef):
            services[d.full_name] = d
        elif isinstance(d, ActionDef):
            actions[d.full_name] = d
    if manifest is not None:
        for s in manifest.services:
            services[s.type.full_name] = s.type
        for a in manifest.actions:
            actions[a.type.full_name] = a.type

    modules: dict[str, ModulePlan] = {}
    consts: dict[str, Constants] = {}

    def module(pkg: str, ns: str) -> ModulePlan:
        name = f"{pkg}.{ns}"
        if name not in modules:
            modules[name] = ModulePlan(pkg, ns)
            consts[name] = Constants()
        return modules[name]

    for full_name in _dependency_order(definitions):
        msg = definitions[full_name]
        mod = module(msg.package, msg.namespace)
        mod.classes.append(plain_class(msg, mod))
    for full_name in sorted(services):
        srv = services[full_name]
        if srv.request.full_name in definitions and srv.response.full_name in definitions:
            module(srv.package, "srv").services.append(ServiceHolder(srv.name, srv.full_name))
    for full_name in sorted(actions):
        act = actions[full_name]
        if all(part.full_name in definitions for part in act.parts):
            module(act.package, "action").actions.append(ActionHolder(act.name, act.full_name))

    module_of = {ct.key: ct.module for ct in codecs.values()}
    entries: list[CodecEntry] = []
    for key in sorted(codecs, key=lambda k: (k[1] != NATIVE, k[1], k[2], k[0])):
        ct = codecs[key]
        mod = module(ct.package, ct.namespace)
        slots = None        # the encoder reading rclpy's slots (not in the packed profile)
        if ct.profile == PACKED:
            functions = PackedLowering(ct.module, consts[ct.module], module_of).packed_functions(ct)
        else:
            low = Lowering(ct.module, consts[ct.module], module_of)
            slots = low.encoder(ct, slots=True)
            functions = [low.encoder(ct), slots, low.decoder(ct)]
        mod.functions += functions
        enc, dec = (f for f in functions if f is not slots and f.name.startswith(("enc", "dec")))
        for used in ct.uses:
            mod.need_import(module_of[used])
        entries.append(CodecEntry(ct.full_name, ct.profile, ct.key, module_alias(ct.module), enc.name, dec.name,
                                  ct.variant, slots.name if slots is not None else ""))
    for name, mod in modules.items():
        mod.constants = consts[name].lines
        mod.imports.sort()
        text = "\n".join(line for fn in mod.functions for line in fn.body)
        mod.bits_imports = [h for h in BITS_HELPERS if f"_{h}(" in text]

    # A service's request and response come from its one file: read each file once.
    files = {lib.source_of(n) for n in (*definitions, *services, *actions)}
    local_files = {Path(lib.source_of(n)).resolve() for n in lib.local_names()}
    sources = sorted((source_label(f, lib), _digest(f)) for f in files)
    ordered = [modules[p] for p in sorted(modules)]
    ros_imports = sorted((type_key(n), *_ros_import(n)) for n in definitions)
    ros_layouts = sorted((type_key(n), repr(ros_layout(d))) for n, d in definitions.items())
    plain_keys = sorted((type_key(n), module_alias(_ros_module(n)), n.split("/")[2]) for n in definitions)
    fingerprints = manifest_fingerprints(manifest, builder) if manifest is not None else {}
    return PackagePlan(package, sources, manifest_label, manifest, ordered, entries,
                       ros_imports, ros_layouts, plain_keys, sorted(set(skipped)), fingerprints,
                       package_digest(fingerprints) if manifest is not None else None,
                       ros_interfaces=_local_packages(lib, [*definitions, *services]),
                       source_paths=sorted((Path(f), Path(f).resolve() in local_files)
                                           for f in files if f is not None),
                       seal_fingerprints=(seal_fingerprints(manifest, builder)
                                          if manifest is not None else {}))


def _local_packages(lib: InterfaceLibrary, used: list[str]) -> list[tuple[str, str, str]]:
    from uwgen.typesupport import build_digest

    local = set(lib.local_names())
    dirs = {Path(lib.source_of(n)).parent.parent for n in used if n in local}
    return sorted((d.name, source_label(d, lib), build_digest(d)) for d in dirs)


# Helpers of uwgen.runtime.wire.bits that generated modules may call (imported as _name).
BITS_HELPERS = (
    "end", "enum_index", "enum_indices", "finish", "from_time_of_day", "from_time_since", "get_bools",
    "get_bytes", "get_count", "get_float", "get_floats", "get_indices", "get_text", "get_texts",
    "get_uints", "put_bools", "put_bytes", "put_count", "put_float", "put_floats", "put_indices",
    "put_text", "put_uint", "put_uints", "quantize", "quantize_all", "start", "time_of_day", "time_since",
    "bshort",
)


def _python_safe(msg: MessageDef) -> MessageDef:
    """Generated (and rclpy) classes need Python identifiers: refuse keywords early."""
    if keyword.iskeyword(msg.name):
        raise DefinitionError(SourceRef(msg.source, 1, 1) if msg.source else None,
                              f"message name '{msg.name}' is a Python keyword; no Python class can carry it")
    for f in msg.fields:
        if keyword.iskeyword(f.name) or f.name.startswith("_"):
            raise DefinitionError(f.where, f"field name '{f.name}' cannot be a Python attribute")
    return msg


def _as_message(d) -> MessageDef:
    if not isinstance(d, MessageDef):
        raise TypeError(f"{d.full_name} is a service, not a message")
    return d


def header_len(msg: MessageDef) -> int:
    """Items before a message's fields on the wire: kind and id, a service's seq, an
    action's goal handle and (results only) status (wire format 3 and 13)."""
    if msg.namespace == "srv":
        return 3
    if msg.namespace == "action":
        return 4 if msg.name.endswith("_Result") else 3
    return 2


def _ros_module(full_name: str) -> str:
    pkg, ns, _name = full_name.split("/")
    return f"{pkg}.{ns}"


def _ros_import(full_name: str) -> tuple[str, str]:
    """(module, class) of a type's rclpy class. rclpy exports an action's goal, result
    and feedback only as attributes of the action class: `Fibonacci.Goal`."""
    pkg, ns, name = full_name.split("/")
    if ns == "action":
        base, _, part = name.rpartition("_")
        return f"{pkg}.{ns}", f"{base}.{part}"
    return f"{pkg}.{ns}", name


def _dependency_order(definitions: dict[str, MessageDef]) -> list[str]:
    order: list[str] = []
    seen: set[str] = set()

    def visit(name: str) -> None:
        if name in seen:
            return
        seen.add(name)
        for f in definitions[name].fields:
            if not f.type.is_primitive and f.type.base in definitions:
                visit(f.type.base)
        order.append(name)

    for name in sorted(definitions):
        visit(name)
    return order
