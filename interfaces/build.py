"""Build and install the node's interface packages into this Python's prefix: daddy_interfaces
(the Replan action) and, where no ROS 2 bond package is importable, bond (the bond/msg/Status
heartbeat nav2's lifecycle manager exchanges with its nodes, field for field as bond_core's).

    python interfaces/build.py            (make does this when it bootstraps .venv)

With a system ROS 2 sourced (``AMENT_PREFIX_PATH`` names a prefix with
rosidl_default_generators) its generators are used; otherwise those of the registry's ROS 2
Jazzy wheels installed in this prefix (requirements/interfaces.txt). The wheels were built on a
manylinux image and their CMake exports name that image's Python include and site-packages
directories; where those do not exist here they are pointed at this interpreter's (the only
change made to installed files). A colcon workspace builds daddy_interfaces as any ament_cmake
package: ``colcon build --base-paths src src/daddy_ros/interfaces/daddy_interfaces``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

HERE = Path(__file__).resolve().parent
# package directory -> the module that shows it is installed
PACKAGES = {HERE / "bond": "bond.msg", HERE / "daddy_interfaces": "daddy_interfaces.action"}
GENERATORS = "share/rosidl_default_generators/cmake/rosidl_default_generatorsConfig.cmake"
# the wheels' build image: its include and site-packages directories, in their CMake exports
WHEEL_BUILD_PATHS = {
    "/opt/python/cp311-cp311/include/python3.11": sysconfig.get_paths()["include"],
    "/opt/python/cp311-cp311/lib/python3.11/site-packages": sysconfig.get_paths()["purelib"],
}


def ament_prefixes() -> list[str]:
    """The prefixes to build against: a sourced ROS 2 with the generators, else this one."""
    sourced = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
               if p and (Path(p) / GENERATORS).exists()]
    if sourced:
        return sourced + [sys.prefix]
    if not (Path(sys.prefix) / GENERATORS).exists():
        raise SystemExit("interfaces: rosidl_default_generators not found: install "
                         "requirements/interfaces.txt or source a ROS 2 installation")
    return [sys.prefix]


def fix_wheel_exports(prefix: Path) -> int:
    """Point the wheels' CMake exports at this interpreter's directories where the build
    image's do not exist here; the number of files changed."""
    changed = 0
    moves = {old: new for old, new in WHEEL_BUILD_PATHS.items() if not Path(old).exists()}
    for f in (prefix / "share").glob("*/cmake/*.cmake"):
        text = f.read_text()
        fixed = text
        for old, new in moves.items():
            fixed = fixed.replace(old, new)
        if fixed != text:
            f.write_text(fixed)
            changed += 1
    return changed


def imports(module: str) -> bool:
    return subprocess.run([sys.executable, "-c", f"import {module}"],
                          capture_output=True).returncode == 0


def build(package: Path, prefixes: list[str], cmake: str) -> None:
    """Configure, build and install one ament_cmake interface package into this prefix."""
    prefix, out = Path(sys.prefix), Path(sys.prefix) / "build" / package.name
    env = dict(os.environ, AMENT_PREFIX_PATH=os.pathsep.join(prefixes),
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    steps = [
        [cmake, "-S", str(package), "-B", str(out), f"-DCMAKE_INSTALL_PREFIX={prefix}",
         f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}", f"-DPython3_EXECUTABLE={sys.executable}",
         "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release"],
        [cmake, "--build", str(out), "-j", str(min(os.cpu_count() or 1, 4))],
        [cmake, "--install", str(out)],
    ]
    for cmd in steps:
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            sys.stderr.write(r.stdout[-4000:] + r.stderr[-4000:])
            raise SystemExit(f"interfaces: {package.name}: {' '.join(cmd[:2])} failed "
                             f"({r.returncode})")


def main() -> int:
    prefixes = ament_prefixes()
    if prefixes == [sys.prefix]:
        fix_wheel_exports(Path(sys.prefix))
    cmake = shutil.which("cmake", path=f"{Path(sys.prefix) / 'bin'}{os.pathsep}"
                                       f"{os.environ['PATH']}")
    if cmake is None:
        raise SystemExit("interfaces: cmake not found (requirements/interfaces.txt installs it)")
    for package, module in PACKAGES.items():
        if package.name == "bond" and imports(module) and not (
                Path(sys.prefix) / "build" / "bond").exists():
            print("interfaces: bond: the installed ROS 2 bond package is used")
            continue
        build(package, prefixes, cmake)
        if not imports(module):
            raise SystemExit(f"interfaces: {package.name} built, but {module} does not import")
        print(f"interfaces: {package.name} installed in {sys.prefix}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
