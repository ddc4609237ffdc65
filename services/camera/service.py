"""The camera service's Zenoh face: ``objscan/{robot}/camera/capture`` → one ``RGBDFrame``.

The backend (sim, realsense, replay) is chosen at start; the orchestrator cannot tell them apart. For
real cameras the frame is stamped with the camera pose the arm believes (asked from ``arm/state``); the
sim's twin stamps its own belief; a replay returns what was recorded.
"""

from __future__ import annotations

import numpy as np

from common import keys
from common.api import CaptureRequest
from common.codec import Message
from common.errors import ObjscanError
from common.messages import JointState, RGBDFrame
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.camera.factory import make_camera


class CameraService(Service):
    name = "camera"

    async def setup(self) -> None:
        opts = self.settings.options
        self.backend = opts.get("backend", "sim")
        config: dict[str, object] = {"backend": self.backend}
        if self.backend == "sim":
            # generous: the twin renders in ~60 ms, but a loaded 2-core machine can stall it for seconds
            config.update(width=opts.get("width", 640), height=opts.get("height", 480), timeout_s=60.0)
        elif self.backend == "realsense":
            config.update(width=opts.get("width", 640), height=opts.get("height", 480))
            if opts.get("playback"):
                config["playback_file"] = opts["playback"]
        elif self.backend == "replay":
            config["session_dir"] = opts["session"]
        self.camera = make_camera(config, render_request=self._render if self.backend == "sim" else None)
        await self.run_cpu(self.camera.connect)
        self.captures = 0
        self.queryable(keys.camera_capture(self.robot), self.capture, budget=COMMAND_BUDGET)

    async def _render(self, T_base_camera: np.ndarray | None, width: int, height: int) -> RGBDFrame:
        reply = await self.request(keys.sim(self.robot, "render"), CaptureRequest(width=width, height=height),
                                   timeout=20.0)
        assert isinstance(reply, RGBDFrame)
        return reply

    async def _arm_camera_pose(self) -> np.ndarray | None:
        try:
            state = await self.request(keys.arm(self.robot, "state"), timeout=2.0)
        except ObjscanError:
            return None
        return state.T_base_camera if isinstance(state, JointState) else None

    async def capture(self, msg: Message | None, ctx: QueryContext) -> RGBDFrame:
        if self.backend == "sim":
            frame = await self.camera.acapture(None)
        else:
            pose = await self._arm_camera_pose() if self.backend == "realsense" else None
            frame = await self.run_cpu(self.camera.capture, pose)
        self.captures += 1
        return frame

    async def teardown(self) -> None:
        await self.run_cpu(self.camera.disconnect)

    def health_info(self) -> dict[str, object]:
        return {"backend": self.backend, "captures": self.captures}


def main() -> None:
    p = service_arg_parser("objscan camera service")
    p.add_argument("--backend", choices=["sim", "realsense", "replay", "real"], default="sim")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--session", help="replay: the session folder to serve frames from")
    p.add_argument("--playback", help="realsense: play a .db3 recording instead of a live camera")
    args = p.parse_args()
    backend = "realsense" if args.backend == "real" else args.backend
    if backend == "replay" and not args.session:
        p.error("--backend replay needs --session SESSION_DIR")
    run_service(lambda: CameraService(settings_from_args(args, backend=backend, width=args.width,
                                                         height=args.height, session=args.session,
                                                         playback=args.playback)))
