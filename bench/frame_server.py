"""A minimal service that serves one 848x480 RGB-D frame: the far end of ``objscan bench transport``."""

from __future__ import annotations

import numpy as np

from common.messages import RGBDFrame, d435_intrinsics
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args

FRAME_KEY = "objscan/bench/frame"


def make_frame(seed: int = 0) -> RGBDFrame:
    rng = np.random.default_rng(seed)
    return RGBDFrame(color=rng.integers(0, 255, (480, 848, 3), dtype=np.uint8),
                     depth=rng.integers(300, 3000, (480, 848), dtype=np.uint16),
                     intrinsics=d435_intrinsics(848, 480),
                     T_base_camera=np.eye(4))


class FrameServer(Service):
    name = "bench-frame"

    async def setup(self) -> None:
        self.frame = make_frame()
        self.queryable(FRAME_KEY, self.serve)

    async def serve(self, msg, ctx: QueryContext) -> RGBDFrame:  # noqa: ANN001
        return self.frame


if __name__ == "__main__":
    args = service_arg_parser("benchmark frame server").parse_args()
    run_service(lambda: FrameServer(settings_from_args(args)))
