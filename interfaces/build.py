"""Build and install the daddy_interfaces package (the Replan action) into this Python's prefix.

    python interfaces/build.py            (make does this when it bootstraps .venv)

With a system ROS 2 sourced (``AMENT_PREFIX_PATH`` names a prefix with
rosidl_default_generators) its generators are used; otherwise those of the registry's ROS 2
Jazzy wheels installed in this prefix (requirements/interfaces.txt). The wheels were built on a
manylinux image and their CMake exports name that image's Python include and site-packages
directories; where those do not exist here they are pointed at this interpreter's (the only
change made to installed files). A colcon workspace builds the package as any ament_cmake one:
``colcon build --base-paths src src/daddy_ros/interfaces``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGE = HERE / "daddy_interfaces"
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


def main() -> int:
    prefix = Path(sys.prefix)
    prefixes = ament_prefixes()
    if prefixes == [sys.prefix]:
        fix_wheel_exports(prefix)
    cmake = shutil.which("cmake", path=f"{prefix / 'bin'}{os.pathsep}{os.environ['PATH']}")
    if cmake is None:
        raise SystemExit("interfaces: cmake not found (requirements/interfaces.txt installs it)")
    build = prefix / "build" / "daddy_interfaces"
    env = dict(os.environ, AMENT_PREFIX_PATH=os.pathsep.join(prefixes),
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    steps = [
        [cmake, "-S", str(PACKAGE), "-B", str(build), f"-DCMAKE_INSTALL_PREFIX={prefix}",
         f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}", f"-DPython3_EXECUTABLE={sys.executable}",
         "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release"],
        [cmake, "--build", str(build), "-j", str(min(os.cpu_count() or 1, 4))],
        [cmake, "--install", str(build)],
    ]
    for cmd in steps:
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            sys.stderr.write(r.stdout[-4000:] + r.stderr[-4000:])
            raise SystemExit(f"interfaces: {' '.join(cmd[:2])} failed ({r.returncode})")
    check = subprocess.run([sys.executable, "-c", "from daddy_interfaces.action import Replan"],
                           capture_output=True, text=True)
    if check.returncode != 0:
        sys.stderr.write(check.stderr)
        raise SystemExit("interfaces: built, but daddy_interfaces does not import")
    print(f"interfaces: daddy_interfaces installed in {prefix}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
