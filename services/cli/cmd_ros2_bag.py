"""``objscan ros2-bag SESSION --out OUT``: a session's recording as a ROS 2 bag folder (MCAP storage).

``ros2 bag play OUT`` then replays the scan into any ROS 2 graph (RViz, Foxglove) with the topics of the live
ROS 2 face (docs/ros2.md). ``objscan export SESSION --ros2-bag OUT`` writes the same bag (its options come from
``add_ros2_bag_options``, its writing from ``write_ros2_bag``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from services.cli import outcome


def add_ros2_bag_options(p: argparse.ArgumentParser, *, required: bool, flag: str, json_flag: bool = True) -> None:
    """The bag's options on a parser: the output folder (``flag``), the distribution, the hand-eye file."""
    p.add_argument(flag, dest="ros2_bag", required=required, metavar="OUT",
                   help="ROS 2 bag folder to write (metadata.yaml + MCAP); must not exist")
    p.add_argument("--ros2-distro", choices=["humble", "jazzy"], default="jazzy",
                   help="message definitions and type hashes of this ROS 2 distribution (default: %(default)s)")
    p.add_argument("--hand-eye", help="hand-eye calibration file for /tf_static gripper -> camera "
                                      "(default: the mount the arm reported)")
    if json_flag:
        p.add_argument("--json", action="store_true", help="print the result (counts per topic) as JSON")


def write_ros2_bag(session: str, args: Any) -> int:
    """Write the bag the parsed options ask for; print what was written; the exit code."""
    from services.calibration.file import load_calibration
    from services.ros2.bag import write_bag

    try:
        X = load_calibration(args.hand_eye).T_gripper_camera if args.hand_eye else None
        summary = write_bag(session, args.ros2_bag, distro=args.ros2_distro, T_gripper_camera=X)
    except Exception as exc:
        return outcome.report_error("ros2-bag", exc, as_json=args.json)
    result = summary.as_dict()
    if args.json:
        outcome.print_json(result)
    else:
        print(f"wrote {result['bag']}: {result['messages']} messages on {len(result['counts'])} topics "
              f"({result['distro']}); play it with: ros2 bag play {Path(result['bag']).resolve()}")
        if result["skipped"]:
            print(f"  {result['skipped']} recorded messages could not be decoded and are not in the bag")
    return 0


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("ros2-bag", help="write a session's recording as a ROS 2 bag (ros2 bag play OUT)",
                       description="Convert a session's recording (session.mcap, every part) into a ROS 2 bag "
                                   "folder with the ROS 2 face's topics and the recorded timestamps.")
    p.add_argument("session", help="session folder (or one session.mcap)")
    add_ros2_bag_options(p, required=True, flag="--out")
    p.set_defaults(func=lambda args: write_ros2_bag(args.session, args))
