"""``objscan devices``: the hardware this machine sees — RealSense cameras and the servos on a DYNAMIXEL bus.

Cameras come from pyrealsense2's context (serial, firmware, USB type). Servos answer a broadcast ping on
``--port`` (ID, model, firmware); ``--emulate-bus`` pings an emulated bus of the robot configuration's
servos instead (PAPRAS by default), to try the command without hardware. Nothing is written to a device.
"""

from __future__ import annotations

import json
from typing import Any

from services.cli.outcome import require_path


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("devices", help="list RealSense cameras and the servos found on a DYNAMIXEL bus",
                       description="Cameras via pyrealsense2 (serial, firmware, USB type); servos on --port via a "
                                   "broadcast ping (ID, model, firmware).")
    p.add_argument("--port", help="DYNAMIXEL bus to scan, e.g. /dev/ttyUSB0 (default: no bus scan)")
    p.add_argument("--baud", type=int, default=1_000_000, help="bus baud rate (default: %(default)s)")
    p.add_argument("--emulate-bus", action="store_true",
                   help="scan an emulated bus of the robot configuration's servos (no hardware needed)")
    p.add_argument("--robot-config", help="robot configuration YAML for --emulate-bus (default: PAPRAS)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print one JSON object (cameras, bus, servos; or the error) instead of tables")
    p.set_defaults(func=run)


def list_cameras() -> tuple[list[dict[str, str]], str | None]:
    """Attached RealSense devices, and why none could be listed (pyrealsense2 missing), if so."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        return [], f"pyrealsense2 is not installed: {exc}"
    out = []
    ci = rs.camera_info
    for dev in rs.context().query_devices():
        entry = {}
        for key, info in (("name", ci.name), ("serial", ci.serial_number), ("firmware", ci.firmware_version),
                          ("usb", ci.usb_type_descriptor)):
            if dev.supports(info):
                entry[key] = dev.get_info(info)
        out.append(entry)
    return out, None


def list_servos(port: str | None, baud: int, emulate: bool, robot_config: str | None) -> list[dict[str, Any]]:
    from services.arm.drivers.dynamixel.driver import scan_bus

    if not emulate:
        return scan_bus(port, baud) if port else []
    from services.arm.drivers.dynamixel.emulator import DynamixelBusEmulator, servos_for
    from services.arm.drivers.dynamixel.robot_config import load_robot_config

    with DynamixelBusEmulator(servos_for(load_robot_config(robot_config))) as emu:
        return scan_bus(emu.port, baud)


def run(args) -> int:  # noqa: ANN001
    cameras, why = list_cameras()
    bus = "emulated" if args.emulate_bus else args.port
    if args.robot_config:  # a missing file is bad input, said before any bus is opened
        require_path(args.robot_config, "robot configuration")
    servos = list_servos(args.port, args.baud, args.emulate_bus, args.robot_config)
    if args.json_output:
        print(json.dumps({"cameras": cameras, "cameras_note": why, "bus": bus, "servos": servos}, indent=2))
        return 0
    print(f"cameras: {len(cameras)}" + (f" ({why})" if why else ""))
    for c in cameras:
        print(f"  {c.get('name', '?'):<28} serial {c.get('serial', '?'):<14} firmware {c.get('firmware', '?'):<12} "
              f"USB {c.get('usb', '?')}")
    if bus is None:
        print("servos: no bus scanned (give --port /dev/ttyUSB0, or --emulate-bus)")
        return 0
    print(f"servos on {bus}: {len(servos)}")
    for s in servos:
        print(f"  ID {s['id']:>3}  {s['model']:<18} (model number {s['model_number']:>5})  firmware {s['firmware']}")
    return 0
