"""`uwgen build`: generate the codec package (and bridges) from interfaces and a manifest."""
from __future__ import annotations

import argparse
import logging
import shlex
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from uwgen.buildinfo import make_record
from uwgen.errors import ErrorList
from uwgen.codegen.generator import plan_build
from uwgen.codegen.render import render_package, stale_files, write_package
from uwgen.codegen.ir import ProfileError
from uwgen.codegen.vendor import VendorError
from uwgen.commands.options import add_folders, add_manifest
from uwgen.manifest.model import NATIVE, PROFILES
from uwgen.idl.model import DefinitionError
from uwgen.manifest.loader import MANIFEST_NAME, ManifestError, find_manifest

HELP = "generate CBOR codecs and bridge nodes from .msg/.srv/.action folders and a manifest"
EXIT_STALE = 1
EXIT_INPUT = 2

log = logging.getLogger("uwgen.build")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_folders(p, "folders of interfaces (<package>/msg/*.msg, <package>/srv/*.srv, "
                   "<package>/action/*.action); every interface in them is built. With none "
                   "(and no -m), the builds listed under [tool.uwgen] in ./pyproject.toml are run")
    add_manifest(p, help=f"default: DIR/{MANIFEST_NAME} of the first DIR, if present")
    p.add_argument("-o", "--out", type=Path,
                   help="the package folder to write (default: generated/<package>)")
    p.add_argument("--package", help="generated package name (default: the manifest's, or uwgen_<DIR name>)")
    p.add_argument("--type", dest="types", action="append", default=[], metavar="TYPE",
                   help="also build this installed type (pkg/msg/Name, pkg/srv/Name or "
                        "pkg/action/Name); repeatable")
    p.add_argument("--all-installed", action="store_true",
                   help="also build every interface installed in the environment")
    p.add_argument("--profile", dest="profiles", action="append", choices=PROFILES,
                   help="profiles to build the folders' interfaces in (default: native); repeatable")
    p.add_argument("--no-installed", action="store_true",
                   help="do not look for interfaces in installed ROS packages")
    p.add_argument("--ros", action="store_true",
                   help="also build rclpy type support for the interface packages in the folders "
                        "(as `uwgen ros-interfaces DIR` does; cached outside the source tree)")
    p.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 if the package on disk differs from what would be generated")


@dataclass
class BuildSpec:
    folders: list[Path]
    manifest: Path | None
    out: Path | None
    package: str | None
    types: list[str]
    all_installed: bool
    profiles: tuple[str, ...]
    installed: bool


def specs_from_pyproject(start: Path) -> tuple[Path, list[BuildSpec]]:
    for folder in [start, *start.parents]:
        pyproject = folder / "pyproject.toml"
        if pyproject.is_file():
            data = tomllib.loads(pyproject.read_text(encoding="utf-8"))
            settings = data.get("tool", {}).get("uwgen")
            if settings is None:
                continue   # a pyproject.toml of something else: look further up
            builds = settings.get("builds")
            if not builds:
                raise DefinitionError(pyproject, "no [tool.uwgen] builds listed; name a folder: uwgen build DIR")
            specs = []
            for b in builds:
                specs.append(BuildSpec(
                    folders=[folder / s for s in b.get("sources", [])],
                    manifest=folder / b["manifest"] if "manifest" in b else None,
                    out=folder / b["out"] if "out" in b else None,
                    package=b.get("package"), types=list(b.get("types", [])),
                    all_installed=bool(b.get("all_installed", False)),
                    profiles=tuple(b.get("profiles", [NATIVE])), installed=True))
            return folder, specs
    raise DefinitionError(None, NO_BUILDS.format(here=start))


NO_BUILDS = """no folder given, and no pyproject.toml with [tool.uwgen] builds in {here} or above it.
  Build a folder of interfaces (its uwgen.yaml is the manifest):  uwgen build DIR [-m MANIFEST] [-o OUT]
  Build a manifest that names installed types only:               uwgen build -m MANIFEST
  Or list your builds in ./pyproject.toml for a bare `uwgen build`:
    [tool.uwgen]
    builds = [{{ sources = ["interfaces"] }}]"""


def run(args: argparse.Namespace) -> int:
    try:
        if args.folders or args.manifest:
            folders = list(args.folders)
            if not folders and args.manifest is not None:
                # A manifest alone: its folder's interface packages, if it has any, else
                # only installed types.
                from uwgen.typesupport import package_dirs
                if package_dirs(args.manifest.parent):
                    folders = [args.manifest.parent]
            specs = [BuildSpec(folders, args.manifest, args.out, args.package, args.types,
                               args.all_installed, tuple(args.profiles or (NATIVE,)),
                               not args.no_installed)]
            root = Path.cwd()
            again = None
        else:
            root, specs = specs_from_pyproject(Path.cwd())
            again = "uwgen build"
        stale = []
        for spec in specs:
            stale += build(spec, root, check=args.check)
    except ErrorList as exc:
        for error in exc.errors:
            print(f"uwgen build: {error}", file=sys.stderr)
        print(f"uwgen build: {exc.summary()}", file=sys.stderr)
        return EXIT_INPUT
    except (DefinitionError, ProfileError, ManifestError, VendorError) as exc:
        print(f"uwgen build: {exc}", file=sys.stderr)
        return EXIT_INPUT
    if args.ros and not args.check:
        from uwgen.commands.ros_interfaces import InputError, ensure_folders
        from uwgen.typesupport import BuildError
        try:
            folders = list(dict.fromkeys(f for spec in specs for f in spec.folders))
            for env in ensure_folders(folders, quiet=True):
                log.info("rclpy type support of %s: %s", env.package, env.prefix or "installed")
        except InputError as exc:
            print(f"uwgen build: {exc}", file=sys.stderr)
            return EXIT_INPUT
        except BuildError as exc:
            print(f"uwgen build: {exc}", file=sys.stderr)
            return EXIT_STALE
    if args.check and stale:
        print("uwgen build --check: generated code is stale:", file=sys.stderr)
        for line in stale:
            print(f"  {line}", file=sys.stderr)
        again = again or shlex.join(rebuild_command(specs[0], root))
        print(f"run `{again}` (in {root}) and commit the result", file=sys.stderr)
        return EXIT_STALE
    return 0


def _manifest_of(spec: BuildSpec) -> Path | None:
    if spec.manifest is None and spec.folders:
        return find_manifest(spec.folders[0])
    return spec.manifest


def rebuild_command(spec: BuildSpec, root: Path, package: str | None = None,
                    with_out: bool = True) -> list[str]:
    """The shortest `uwgen build` command line (run in `root`) that makes this build again."""
    cmd = ["uwgen", "build", *[_relative(f, root) for f in spec.folders]]
    manifest = _manifest_of(spec)
    default = find_manifest(spec.folders[0]) if spec.folders else None
    if manifest is not None and (default is None or Path(default).resolve() != Path(manifest).resolve()):
        cmd += ["-m", _relative(manifest, root)]
    if spec.package:
        cmd += ["--package", spec.package]
    name = spec.package or package
    if with_out and spec.out is not None and (name is None or Path(spec.out).resolve() != (root / "generated" / name).resolve()):
        cmd += ["-o", _relative(spec.out, root)]
    for t in spec.types:
        cmd += ["--type", t]
    if spec.all_installed:
        cmd.append("--all-installed")
    if tuple(spec.profiles) != (NATIVE,):
        for profile in spec.profiles:
            cmd += ["--profile", profile]
    if not spec.installed:
        cmd.append("--no-installed")
    return cmd


def build(spec: BuildSpec, root: Path, check: bool = False) -> list[str]:
    """Generate one package; returns what is stale (check) or what changed (write)."""
    t0 = time.perf_counter()
    manifest_path = _manifest_of(spec)
    plan = plan_build(spec.folders, spec.types, manifest_path, spec.package, spec.profiles,
                      spec.installed, spec.all_installed,
                      _relative(manifest_path, root) if manifest_path else None)
    for reason in plan.skipped:
        log.warning("left out: %s", reason)
    out = spec.out or (root / "generated" / plan.package)
    if manifest_path is not None:
        plan.built_from = make_record(manifest_path, plan.source_paths, root,
                                      rebuild_command(spec, root, plan.package, with_out=False))
    files = render_package(plan)
    if check:
        return stale_files(files, out)
    changed = write_package(files, out)
    log.info("%s: %d codecs in %d modules -> %s (%d files changed) in %.2f s",
             plan.package, len(plan.codecs), len(plan.modules), _relative(out, root), len(changed),
             time.perf_counter() - t0)
    return changed


def _relative(path: Path, root: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(root.resolve()))
    except ValueError:
        return str(path)
