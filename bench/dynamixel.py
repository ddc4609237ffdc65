"""``objscan bench dynamixel``: the DYNAMIXEL driver on the emulated PAPRAS bus (DYNAMIXEL-P, through
dynamixel-sdk as packets on a pty).

- ``connect_ms``: ping + model check + firmware + hardware error + EEPROM/profile writes + hold + torque on,
  for the 6 joint servos and the gripper.
- ``setpoint_ms_median``/``_p95``: one streamed set-point (sync write of goals + sync read of positions);
  it must fit the 10 ms period of 100 Hz streaming.
- ``move_s``/``move_planned_s``: a 0.4 rad joint move streamed in real time and settled, against the
  trajectory's own duration (the settle check's cost is the difference).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def run(quick: bool = False) -> dict[str, Any]:
    from services.arm.arm import ArmConfig, ArmController
    from services.arm.drivers.dynamixel import DynamixelConfig
    from services.arm.drivers.dynamixel.driver import DynamixelArmDriver
    from services.arm.drivers.dynamixel.emulator import DynamixelBusEmulator

    n = 100 if quick else 300
    with DynamixelBusEmulator() as emu:
        driver = DynamixelArmDriver(DynamixelConfig(port=emu.port))
        t = time.perf_counter()
        driver.connect()
        connect_ms = (time.perf_counter() - t) * 1000
        q = np.asarray(driver.config.home)
        cycle = []
        for k in range(n):
            t = time.perf_counter()
            driver.write_setpoint(q + 0.0005 * k)
            cycle.append((time.perf_counter() - t) * 1000)
        driver.settle()
        ctl = ArmController(driver, ArmConfig(realtime=True))
        ctl.connect()  # already connected: it only reads where the arm is
        target = q + np.array([0.4, -0.2, 0.2, 0.3, -0.2, 0.4])
        t = time.perf_counter()
        info = ctl.move_joints(target)
        move_s = time.perf_counter() - t
        err = float(np.max(np.abs(driver.read_joints() - target)))
        driver.close()
    return {"connect_ms": connect_ms, "setpoint_ms_median": float(np.median(cycle)),
            "setpoint_ms_p95": float(np.percentile(cycle, 95)), "setpoints": n, "move_s": move_s,
            "move_planned_s": float(info["duration_s"]), "move_final_error_rad": err}
