"""A small real service for runtime tests: echo, CPU burn, an RGB-D frame and a large colored cloud."""

from __future__ import annotations

import time

import numpy as np

from common.messages import Ok, PointCloud, Request, RGBDFrame, d435_intrinsics
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args


def _burn(seconds: float) -> int:
    """Pure-Python CPU burn (holds the GIL between switches, the worst case for the loop)."""
    end, n = time.perf_counter() + seconds, 0
    while time.perf_counter() < end:
        n += sum(i * i for i in range(200))
    return n


class EchoService(Service):
    name = "echo"

    async def setup(self) -> None:
        rng = np.random.default_rng(0)
        self.frame = RGBDFrame(
            color=rng.integers(0, 255, (480, 848, 3), dtype=np.uint8),
            depth=rng.integers(0, 4000, (480, 848), dtype=np.uint16),
            intrinsics=d435_intrinsics(848, 480),
            T_base_camera=np.eye(4))
        n = 300_000
        self.cloud = PointCloud(xyz=rng.normal(size=(n, 3)).astype(np.float32),
                                rgb=rng.integers(0, 255, (n, 3), dtype=np.uint8),
                                normals=rng.normal(size=(n, 3)).astype(np.float32))
        prefix = f"objscan/test/{self.instance}"
        self.queryable(f"{prefix}/echo", self.echo)
        self.queryable(f"{prefix}/burn", self.burn)
        self.queryable(f"{prefix}/frame", self.get_frame)
        self.queryable(f"{prefix}/cloud", self.get_cloud)
        self.queryable(f"{prefix}/crash", self.crash)

    async def echo(self, msg, ctx: QueryContext):
        return msg if msg is not None else Ok(info={"empty": True})

    async def burn(self, msg, ctx: QueryContext):
        seconds = float(msg.params.get("seconds", 2.0)) if isinstance(msg, Request) else 2.0
        n = await self.run_cpu(_burn, seconds)
        return Ok(info={"iterations": n})

    async def get_frame(self, msg, ctx: QueryContext):
        return self.frame

    async def get_cloud(self, msg, ctx: QueryContext):
        return self.cloud

    async def crash(self, msg, ctx: QueryContext):
        raise RuntimeError("deliberate handler bug")


def main() -> None:
    args = service_arg_parser("echo test service").parse_args()
    run_service(lambda: EchoService(settings_from_args(args)))


if __name__ == "__main__":
    main()
