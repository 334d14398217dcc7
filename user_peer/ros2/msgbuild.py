"""The ROS 2 interface packages Kilted's wheels lack, built into this Python environment: ``tf2_msgs`` (for /tf),
``std_srvs`` (for the ownership services), ``nav2_msgs``' NavigateToPose action and ``control_msgs``'
FollowJointTrajectory action (for the bridge's action servers).

PyPI's Kilted wheels ship rclpy, most message packages (``action_msgs`` and ``unique_identifier_msgs``, which
rclpy's actions need, among them) and the whole rosidl tool chain (the generators for C and Python, the C type
supports, their headers and libraries, under the environment's ``include/``, ``lib/`` and ``share/``), but not
``tf2_msgs``, ``std_srvs``, ``nav2_msgs`` or ``control_msgs``. This module does what colcon would do for them,
without CMake or ament: it writes each interface as IDL (the text ``rosidl_adapter`` would make from the
``.msg``/``.srv``; the adapter itself needs catkin_pkg, which the wheels do not bring), runs the generators through
their ``rosidl_cli`` extensions (the ``rosidl`` command itself refuses the wheels' duplicated entry points),
compiles their output with the system's ``gcc``/``g++`` against the wheels' headers, and installs what a colcon
build installs: the ``lib<pkg>__rosidl_*.so`` libraries into the environment's ``lib/`` (which the wheels'
bootstrapper puts on ``LD_LIBRARY_PATH``, where ``rosidl_typesupport_c`` finds them) and the Python package
(``<pkg>/msg``, ``<pkg>/srv`` and the three ``<pkg>_s__rosidl_typesupport_*`` extension modules) into
site-packages. The interfaces are the upstream ones, field for field, so their RIHS01 type hashes are the
upstream hashes and any ROS 2 node matches them.

A package that is importable already (a sourced ROS 2 install, an earlier build) is left alone. Run it with
``python -m user_peer.ros2.msgbuild`` (``make test`` does); it needs a C++ compiler and Python's headers
(Debian: ``apt-get install g++ python3-dev``), and says which is missing.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

__all__ = ["INTERFACES", "MsgBuildError", "missing", "build", "main", "type_hashes"]

INTERFACES: dict[str, dict[str, str]] = {
    "tf2_msgs": {
        "msg/TFMessage.idl": """\
#include "geometry_msgs/msg/TransformStamped.idl"

module tf2_msgs {
  module msg {
    struct TFMessage {
      sequence<geometry_msgs::msg::TransformStamped> transforms;
    };
  };
};
""",
    },
    "std_srvs": {
        "srv/Trigger.idl": """\
module std_srvs {
  module srv {
    struct Trigger_Request {
      uint8 structure_needs_at_least_one_member;
    };
    struct Trigger_Response {
      boolean success;
      string message;
    };
  };
};
""",
    },
    "nav2_msgs": {
        # navigation2's nav2_msgs/action/NavigateToPose.action (main, 2025), the action RViz's Nav2 panel and
        # Nav2's clients send; Kilted's wheels have no nav2_msgs
        "action/NavigateToPose.idl": """\
#include "builtin_interfaces/msg/Duration.idl"
#include "geometry_msgs/msg/PoseStamped.idl"

module nav2_msgs {
  module action {
    struct NavigateToPose_Goal {
      geometry_msgs::msg::PoseStamped pose;
      string behavior_tree;
    };
    module NavigateToPose_Result_Constants {
      const uint16 NONE = 0;
      const uint16 GOAL_REJECTED = 1;
      const uint16 SEND_GOAL_FAILURE = 2;
      const uint16 UNKNOWN = 9000;
      const uint16 FAILED_TO_LOAD_BEHAVIOR_TREE = 9001;
      const uint16 TF_ERROR = 9002;
      const uint16 TIMEOUT = 9003;
    };
    struct NavigateToPose_Result {
      uint16 error_code;
      string error_msg;
    };
    struct NavigateToPose_Feedback {
      geometry_msgs::msg::PoseStamped current_pose;
      builtin_interfaces::msg::Duration navigation_time;
      builtin_interfaces::msg::Duration estimated_time_remaining;
      int16 number_of_recoveries;
      float distance_remaining;
      float position_tracking_error;
      float heading_tracking_error;
    };
  };
};
""",
    },
    "control_msgs": {
        # ros-controls/control_msgs master (6.3.0 on, June 2025: the branch Kilted and Rolling are released from),
        # the action MoveIt's and ros2_control's trajectory clients send; Jazzy's lacks the feedback's two indices
        "msg/JointTolerance.idl": """\
module control_msgs {
  module msg {
    struct JointTolerance {
      string name;
      double position;
      double velocity;
      double acceleration;
    };
  };
};
""",
        "msg/JointComponentTolerance.idl": """\
module control_msgs {
  module msg {
    module JointComponentTolerance_Constants {
      const uint16 X_AXIS = 1;
      const uint16 Y_AXIS = 2;
      const uint16 Z_AXIS = 3;
      const uint16 TRANSLATION = 4;
      const uint16 ROTATION = 5;
    };
    struct JointComponentTolerance {
      string joint_name;
      uint16 component;
      double position;
      double velocity;
      double acceleration;
    };
  };
};
""",
        "action/FollowJointTrajectory.idl": """\
#include "builtin_interfaces/msg/Duration.idl"
#include "control_msgs/msg/JointComponentTolerance.idl"
#include "control_msgs/msg/JointTolerance.idl"
#include "std_msgs/msg/Header.idl"
#include "trajectory_msgs/msg/JointTrajectory.idl"
#include "trajectory_msgs/msg/JointTrajectoryPoint.idl"
#include "trajectory_msgs/msg/MultiDOFJointTrajectory.idl"
#include "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint.idl"

module control_msgs {
  module action {
    struct FollowJointTrajectory_Goal {
      trajectory_msgs::msg::JointTrajectory trajectory;
      trajectory_msgs::msg::MultiDOFJointTrajectory multi_dof_trajectory;
      sequence<control_msgs::msg::JointTolerance> path_tolerance;
      sequence<control_msgs::msg::JointComponentTolerance> component_path_tolerance;
      sequence<control_msgs::msg::JointTolerance> goal_tolerance;
      sequence<control_msgs::msg::JointComponentTolerance> component_goal_tolerance;
      builtin_interfaces::msg::Duration goal_time_tolerance;
    };
    module FollowJointTrajectory_Result_Constants {
      const int32 SUCCESSFUL = 0;
      const int32 INVALID_GOAL = -1;
      const int32 INVALID_JOINTS = -2;
      const int32 OLD_HEADER_TIMESTAMP = -3;
      const int32 PATH_TOLERANCE_VIOLATED = -4;
      const int32 GOAL_TOLERANCE_VIOLATED = -5;
    };
    struct FollowJointTrajectory_Result {
      int32 error_code;
      string error_string;
    };
    struct FollowJointTrajectory_Feedback {
      std_msgs::msg::Header header;
      sequence<string> joint_names;
      trajectory_msgs::msg::JointTrajectoryPoint desired;
      trajectory_msgs::msg::JointTrajectoryPoint actual;
      trajectory_msgs::msg::JointTrajectoryPoint error;
      int32 index;
      sequence<string> multi_dof_joint_names;
      trajectory_msgs::msg::MultiDOFJointTrajectoryPoint multi_dof_desired;
      trajectory_msgs::msg::MultiDOFJointTrajectoryPoint multi_dof_actual;
      trajectory_msgs::msg::MultiDOFJointTrajectoryPoint multi_dof_error;
      int32 multi_dof_index;
    };
  };
};
""",
    },
}
"""Each package's interfaces as ``rosidl_adapter`` writes them from upstream's ``.msg``/``.srv``/``.action``
(comments aside, which do not enter the type hash): ``tf2_msgs/TFMessage``, ``std_srvs/Trigger``,
``nav2_msgs/action/NavigateToPose`` and ``control_msgs/action/FollowJointTrajectory`` (with the two tolerance
messages it holds) only, what the bridge uses."""

_DEPS = (
    "geometry_msgs",
    "trajectory_msgs",
    "std_msgs",
    "builtin_interfaces",
    "service_msgs",
    "action_msgs",
    "unique_identifier_msgs",
)
"""The interface packages the interfaces above refer to (a service's event message holds ``service_msgs``', an
action's goal and result services ``action_msgs``' and ``unique_identifier_msgs``')."""

_RUNTIME = (
    "rosidl_runtime_c",
    "rcutils",
    "rosidl_typesupport_c",
    "rcpputils",
    "rosidl_typesupport_fastrtps_c",
    "rosidl_typesupport_fastrtps_cpp",
    "fastcdr",
    "rosidl_typesupport_introspection_c",
)

_TYPESUPPORTS = ("c", "fastrtps_c", "introspection_c")

log = logging.getLogger("robofabric.ros2.msgbuild")


class MsgBuildError(RuntimeError):
    """A package could not be built: what was missing or what the compiler said."""


def missing(packages: tuple[str, ...] | None = None) -> list[str]:
    """Those of ``packages`` (default: all of :data:`INTERFACES`) that Python cannot import."""
    return [p for p in (packages or tuple(INTERFACES)) if importlib.util.find_spec(p) is None]


def _generate(package: str, src: Path, out: Path) -> None:
    """rosidl's generators (C, Python, and the C type supports) on ``src``'s IDL files into ``out/<kind>``."""
    os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)  # where the generators find their templates
    logging.getLogger("rosidl_cli").setLevel(logging.ERROR)  # the wheels register each extension twice: said once each
    from rosidl_generator_c.cli import GenerateC
    from rosidl_generator_py.cli import GeneratePython
    from rosidl_typesupport_c.cli import GenerateCTypesupport
    from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
    from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

    files = [f"{src}:{rel}" for rel in INTERFACES[package]]
    include = [str(Path(sys.prefix) / "share")]
    for kind, ext in (
        ("c", GenerateC("c")),
        ("py", GeneratePython("py")),
        ("ts_c", GenerateCTypesupport("c")),
        ("fastrtps_c", GenerateFastRTPSCTypesupport("fastrtps_c")),
        ("introspection_c", GenerateIntrospectionCTypesupport("introspection_c")),
    ):
        ext.generate(package, files, include, output_path=out / kind / package)


def type_hashes(package: str, interfaces: dict[str, str] | None = None) -> dict[str, str]:
    """Type name -> RIHS01 hash of each type ``interfaces`` (relative path -> IDL text; default: ``package``'s in
    :data:`INTERFACES`) defines or refers to, as rosidl's type description generator computes them for the built
    libraries; nothing is compiled. Tests compare them with upstream's published hashes."""
    os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    logging.getLogger("rosidl_cli").setLevel(logging.ERROR)
    from rosidl_generator_type_description.cli import HashTypeDescription

    interfaces = INTERFACES[package] if interfaces is None else interfaces
    with tempfile.TemporaryDirectory(prefix=f"robofabric-{package}-hash-") as tmp:
        src = Path(tmp) / "src"
        for rel, text in interfaces.items():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            (src / rel).write_text(text, encoding="utf-8")
        files = HashTypeDescription("type_description").generate_type_hashes(
            package, [f"{src}:{rel}" for rel in interfaces], [str(Path(sys.prefix) / "share")], Path(tmp) / "out"
        )
        return {h["type_name"]: h["hash_string"] for f in files for h in json.loads(Path(f).read_text())["type_hashes"]}


def _include_flags(out: Path) -> list[str]:
    """The generated headers, every wheel's headers, Python's and numpy's; an error naming what is missing."""
    python_include = Path(sysconfig.get_paths()["include"])
    if not (python_include / "Python.h").is_file():
        raise MsgBuildError(
            f"no Python.h in {python_include}: install Python's headers (Debian: apt-get install python3-dev)"
        )
    import numpy

    prefix_include = Path(sys.prefix) / "include"
    dirs = [out / k for k in ("c", "fastrtps_c", "introspection_c")] + [prefix_include]
    dirs += sorted(d for d in prefix_include.iterdir() if d.is_dir())
    dirs += [python_include, Path(numpy.get_include())]
    return [f"-I{d}" for d in dirs]


def _compiler(name: str) -> str:
    found = shutil.which(os.environ.get("CXX" if name == "g++" else "CC", name))
    if found is None:
        raise MsgBuildError(f"no {name} on PATH: install a C and C++ compiler (Debian: apt-get install g++)")
    return found


def _link(cc: str, sources: list[Path], target: Path, libs: list[str], flags: list[str]) -> None:
    """One shared library from ``sources``, linked to ``libs`` (only those it uses are kept)."""
    cmd = [
        cc,
        "-shared",
        "-fPIC",
        "-O1",
        "-w",
        *flags,
        *map(str, sources),
        "-o",
        str(target),
        "-Wl,--as-needed",
        *(f"-l{lib}" for lib in libs),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise MsgBuildError(f"building {target.name} failed:\n{done.stderr[-3000:]}")


def _dep_libs(kind: str) -> list[str]:
    return [f"{d}__{kind}" for d in _DEPS if (Path(sys.prefix) / "lib" / f"lib{d}__{kind}.so").exists()]


def _compile(package: str, out: Path, lib: Path, py: Path) -> None:
    """The five libraries and three extension modules colcon would build for ``package``, into ``lib``
    (``py``: the Python package's directory for the extension modules)."""
    cc, cxx = _compiler("gcc"), _compiler("g++")
    flags = _include_flags(out) + [f"-L{lib}", f"-L{Path(sys.prefix) / 'lib'}", "-Wl,-rpath,$ORIGIN"]
    runtime = [r for r in _RUNTIME if (Path(sys.prefix) / "lib" / f"lib{r}.so").exists()]
    gen_c = f"{package}__rosidl_generator_c"

    def so(kind: str) -> Path:
        return lib / f"lib{package}__{kind}.so"

    _link(
        cc, sorted((out / "c").rglob("*.c")), so("rosidl_generator_c"), _dep_libs("rosidl_generator_c") + runtime, flags
    )
    stage = [
        (cc, sorted((out / "introspection_c").rglob("*.c")), "rosidl_typesupport_introspection_c"),
        (cxx, sorted((out / "fastrtps_c").rglob("*.cpp")), "rosidl_typesupport_fastrtps_c"),
        (cxx, sorted((out / "ts_c").rglob("*.cpp")), "rosidl_typesupport_c"),
    ]
    with ThreadPoolExecutor(3) as pool:
        for f in [
            pool.submit(
                _link, c, srcs, so(kind), [gen_c, *_dep_libs(kind), *_dep_libs("rosidl_generator_c"), *runtime], flags
            )
            for c, srcs, kind in stage
        ]:
            f.result()
    _link(
        cc,
        sorted((out / "py" / package).glob("*/_*_s.c")),
        so("rosidl_generator_py"),
        [
            gen_c,
            f"{package}__rosidl_typesupport_c",
            *_dep_libs("rosidl_generator_py"),
            *_dep_libs("rosidl_generator_c"),
            *runtime,
        ],
        flags,
    )
    with ThreadPoolExecutor(3) as pool:
        for f in [
            pool.submit(
                _link,
                cc,
                [out / "py" / package / f"_{package}_s.ep.rosidl_typesupport_{ts}.c"],
                py / f"{package}_s__rosidl_typesupport_{ts}.so",
                [f"{package}__rosidl_generator_py", f"{package}__rosidl_typesupport_{ts}", gen_c, *runtime],
                flags,
            )
            for ts in _TYPESUPPORTS
        ]:
            f.result()


def build(package: str, *, lib: Path | None = None, site: Path | None = None) -> Path:
    """Generate, compile and install ``package`` (a key of :data:`INTERFACES`); its libraries go to ``lib``
    (default: the environment's ``lib/``), its Python package under ``site`` (default: site-packages).
    Returns the Python package's directory. Raises :class:`MsgBuildError` saying what is missing or failed."""
    if importlib.util.find_spec("rosidl_generator_py") is None:
        raise MsgBuildError("the rosidl generators are not importable: pip install 'robofabric[ros2]' first")
    lib = lib or Path(sys.prefix) / "lib"
    site = site or Path(sysconfig.get_paths()["purelib"])
    with tempfile.TemporaryDirectory(prefix=f"robofabric-{package}-") as tmp:
        work = Path(tmp)
        src = work / "src"
        for rel, text in INTERFACES[package].items():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            (src / rel).write_text(text, encoding="utf-8")
        _generate(package, src, work / "gen")
        staged = work / "py" / package  # the Python package, assembled before it replaces any earlier one
        shutil.copytree(work / "gen" / "py" / package, staged, ignore=shutil.ignore_patterns("*.c"))
        (staged / "__init__.py").touch()
        (staged / "BUILT_BY_ROBOFABRIC").write_text("user_peer.ros2.msgbuild: delete this directory to rebuild\n")
        lib.mkdir(parents=True, exist_ok=True)
        _compile(package, work / "gen", lib, staged)
        target = site / package
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(staged, target)
    return target


def main(argv: list[str] | None = None) -> int:
    """``python -m user_peer.ros2.msgbuild [--force] [PACKAGE...]``: build the missing packages (all of them
    with --force); 0 when all are importable afterwards, 1 with the reason otherwise, 2 for a wrong argument."""
    import argparse

    ap = argparse.ArgumentParser(
        prog="python -m user_peer.ros2.msgbuild",
        description="Build the ROS 2 interfaces the bridge uses and no Kilted wheel ships (type support and Python "
        "package, compiled with the wheels' own rosidl generators and g++), into this environment.",
        epilog="`make test` runs it once per virtual environment. Needs g++ and Python's headers.",
    )
    ap.add_argument(
        "packages", nargs="*", metavar="PACKAGE", help=f"what to build (default: all of {', '.join(INTERFACES)})"
    )
    ap.add_argument("--force", action="store_true", help="build again even when the package is importable")
    a = ap.parse_args(argv)
    force = a.force
    named = tuple(a.packages) or tuple(INTERFACES)
    unknown = [p for p in named if p not in INTERFACES]
    if unknown:
        print(f"unknown package {', '.join(unknown)}: this builds {', '.join(INTERFACES)}", file=sys.stderr)
        return 2
    todo = list(named) if force else missing(named)
    for package in todo:
        start = time.monotonic()
        try:
            where = build(package)
        except (MsgBuildError, OSError) as exc:  # OSError: an environment this user may not write to
            print(f"could not build {package}: {exc}", file=sys.stderr)
            return 1
        print(f"built {package} into {where} in {time.monotonic() - start:.1f} s", flush=True)
    if not todo:
        print(f"already importable: {', '.join(named)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
