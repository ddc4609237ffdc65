"""Run in a child process by test_collision_race.py: motion checks while the object box changes.

Prints one JSON line: checks done, trajectory checks whose answer was not one of the two scenes' answers,
errors. Before the fix this process died (heap corruption, SIGABRT) within a second.
"""

from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np

from services.arm.arm import ArmConfig
from services.arm.collision import CollisionWorld
from services.arm.errors import CollisionError
from services.arm.kinematics import Kinematics
from services.arm.motion import plan_joint_motion


def main(seconds: float) -> None:
    kin = Kinematics(ArmConfig().kinematics)
    world = CollisionWorld(kin)
    q0 = np.array([0.0, -0.3, -0.9, 0.0, 1.2, 0.0])
    traj = plan_joint_motion(q0, q0 + np.array([1.0, 0.3, 0.3, 0.5, -0.5, 1.0]))
    mid = kin.fk(traj.sample(50.0).q[len(traj.sample(50.0).q) // 2])[:3, 3]  # the hand passes through here
    box = (np.asarray(mid, float), np.array([0.08, 0.08, 0.08]))

    def answer() -> str:
        try:
            world.check_trajectory(traj)
            return "free"
        except CollisionError as exc:
            return f"{exc.detail['link_a']}|{exc.detail['link_b']}|{exc.detail['t_approx']}"

    expected = {answer()}
    world.set_object_box(*box)
    expected.add(answer())
    world.clear_object()
    stop = threading.Event()
    out = {"checks": 0, "inconsistent": 0, "errors": [], "scene_changes": 0, "answers": sorted(expected)}

    def checker() -> None:
        while not stop.is_set():
            try:
                if answer() not in expected:
                    out["inconsistent"] += 1
                out["checks"] += 1
            except Exception as exc:  # noqa: BLE001 - reported
                out["errors"].append(repr(exc))

    def toggler() -> None:
        while not stop.is_set():
            try:
                world.set_object_box(*box)
                world.clear_object()
                out["scene_changes"] += 2
            except Exception as exc:  # noqa: BLE001 - reported
                out["errors"].append(repr(exc))

    threads = [threading.Thread(target=checker), threading.Thread(target=checker), threading.Thread(target=toggler)]
    for t in threads:
        t.start()
    time.sleep(seconds)
    stop.set()
    for t in threads:
        t.join()
    out["errors"] = out["errors"][:5]
    print(json.dumps(out))


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 2.0)
