"""``python -m services.arm.drivers.dynamixel emulate``: an emulated PAPRAS bus on a pty, until Ctrl-C."""

from __future__ import annotations

import argparse
import time

from services.arm.drivers.dynamixel.emulator import DynamixelBusEmulator


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m services.arm.drivers.dynamixel")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("emulate", help="emulate the PAPRAS bus: 6 DYNAMIXEL-P servos (IDs 1-6), an RH-P12-RN(A) (ID 111)")
    args = ap.parse_args(argv)
    if args.cmd == "emulate":
        with DynamixelBusEmulator() as emu:
            print(f"emulated DYNAMIXEL bus on {emu.port} (IDs {sorted(emu.servos)}); Ctrl-C to stop", flush=True)
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
