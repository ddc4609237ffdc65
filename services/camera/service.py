"""The camera service's Zenoh face: ``objscan/{robot}/camera/capture`` → one ``RGBDFrame``.

The backend (a name of ``services/camera/registry.py``) is chosen at start and built from the registry; the
service only calls the ``Camera`` interface, and the orchestrator cannot tell backends apart. A backend
whose frames are stamped with the pose given (``pose_from_arm``: realsense) gets the camera pose the arm
believes (asked from ``arm/state``); the sim's twin stamps its own belief; a replay returns what was
recorded; a PNG folder has no pose (``unknown``).

A hand-eye calibration file (``--hand-eye FILE`` or ``$OBJSCAN_HAND_EYE``, written by ``objscan calibrate
hand-eye``) is loaded at start and corrects every live frame's pose (pose source ``given`` or ``sim``; not a
replay's, stamped when recorded, nor an unknown one); the frame's ``meta["hand_eye"]`` says which file and correction.
"""

from __future__ import annotations

import numpy as np

from common import keys
from common.api import CaptureRequest
from common.backend_options import option_pair
from common.codec import Message
from common.errors import ObjscanError
from common.messages import JointState, RGBDFrame
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.calibration.file import HandEyeCalibration, calibration_from_env
from services.camera.base import LIVE_POSE_SOURCES, POSE_SOURCE_KEY
from services.camera.registry import BACKENDS, CameraContext, camera_from_options


def apply_hand_eye(frame: RGBDFrame, hand_eye: HandEyeCalibration | None, path: str | None) -> RGBDFrame:
    """Correct a live frame's pose with the hand-eye calibration and say so in ``meta["hand_eye"]``.

    Only live poses (``LIVE_POSE_SOURCES``): a replay's were stamped (and corrected) when recorded, and an
    unknown pose must stay recognisable as the identity. Whatever the backend, this one rule decides.
    """
    if hand_eye is None or (frame.meta or {}).get(POSE_SOURCE_KEY) not in LIVE_POSE_SOURCES:
        return frame
    frame.T_base_camera = hand_eye.apply(frame.T_base_camera)
    frame.meta = {**(frame.meta or {}), "hand_eye": {
        "file": path, "correction": hand_eye.correction.tolist(),
        "T_gripper_camera": hand_eye.T_gripper_camera.tolist()}}
    return frame


class CameraService(Service):
    name = "camera"

    async def setup(self) -> None:
        opts = self.settings.options
        self.backend = opts.get("backend", "sim")
        # a broken or missing calibration file stops the start: stamping uncorrected poses would be silent
        self.hand_eye, self.hand_eye_path = calibration_from_env(opts.get("hand_eye"))
        self.camera, _ = camera_from_options(self.backend, opts.get("backend_options") or {},
                                             CameraContext(render_request=self._render))
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
        pose = await self._arm_camera_pose() if self.camera.pose_from_arm else None
        frame = apply_hand_eye(await self.camera.acapture(pose), self.hand_eye, self.hand_eye_path)
        self.captures += 1
        return frame

    async def teardown(self) -> None:
        if hasattr(self, "camera"):  # absent when the start failed before the backend was built
            await self.run_cpu(self.camera.disconnect)

    def health_info(self) -> dict[str, object]:
        return {"backend": self.backend, "captures": self.captures, "hand_eye": self.hand_eye_path}


def main() -> None:
    p = service_arg_parser("objscan camera service")
    p.add_argument("--backend", choices=list(BACKENDS), default="sim",
                   help="camera backend (services/camera/registry.py; default: %(default)s)")
    p.add_argument("--width", type=int, default=None,
                   help="image width in pixels, for a backend with a width option (sim, realsense; default: its own)")
    p.add_argument("--height", type=int, default=None,
                   help="image height in pixels, for a backend with a height option (default: its own)")
    p.add_argument("--hand-eye", default=None, metavar="FILE",
                   help="hand-eye calibration file to correct poses with (default: env OBJSCAN_HAND_EYE)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", type=option_pair,
                   help="a backend's own option (repeatable; its keys: docs/extending.md), e.g. replay: "
                        "--option session=DIR, realsense: --option serial=SN, png_folder: --option folder=DIR")
    args = p.parse_args()
    given = dict(args.option)
    for key in ("width", "height"):
        if getattr(args, key) is not None:
            if key in given:
                p.error(f"--option {key}=... and --{key}: give one")
            given[key] = getattr(args, key)
    run_service(lambda: CameraService(settings_from_args(args, backend=args.backend, hand_eye=args.hand_eye,
                                                         backend_options=given)))
