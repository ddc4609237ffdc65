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

import os

import numpy as np

from common import keys
from common.api import CaptureRequest
from common.codec import Message
from common.errors import ObjscanError
from common.messages import JointState, RGBDFrame
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.calibration.file import HandEyeCalibration, calibration_from_env
from services.camera.base import LIVE_POSE_SOURCES, POSE_SOURCE_KEY
from services.camera.registry import BACKENDS, CameraContext, backend_option, camera_from_options


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
        self.camera, _ = camera_from_options(self.backend, opts, CameraContext(render_request=self._render))
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
        await self.run_cpu(self.camera.disconnect)

    def health_info(self) -> dict[str, object]:
        return {"backend": self.backend, "captures": self.captures, "hand_eye": self.hand_eye_path}


def main() -> None:
    p = service_arg_parser("objscan camera service")
    p.add_argument("--backend", choices=list(BACKENDS), default="sim",
                   help="camera backend (services/camera/registry.py; default: %(default)s)")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--session", help="replay: the session folder to serve frames from")
    p.add_argument("--playback", help="realsense: play a .db3 recording instead of a live camera")
    p.add_argument("--serial", default=os.environ.get("OBJSCAN_CAMERA_SERIAL") or None,
                   help="realsense: the camera to open when several are attached (default: env OBJSCAN_CAMERA_SERIAL)")
    p.add_argument("--visual-preset", default=os.environ.get("OBJSCAN_CAMERA_PRESET", "high_accuracy"),
                   help="realsense: D400 depth preset (default: env OBJSCAN_CAMERA_PRESET or %(default)s; 'none' "
                        "leaves the camera's)")
    p.add_argument("--no-exposure-lock", action="store_true",
                   help="realsense: keep auto exposure / white balance on (default: locked after warm-up)")
    p.add_argument("--hand-eye", default=None, metavar="FILE",
                   help="hand-eye calibration file to correct poses with (default: env OBJSCAN_HAND_EYE)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", type=backend_option,
                   help="a backend's own option (repeatable), e.g. png_folder: --option folder=DIR")
    args = p.parse_args()
    options = dict(backend=args.backend, width=args.width, height=args.height, session=args.session,
                   playback=args.playback, hand_eye=args.hand_eye, serial=args.serial,
                   no_exposure_lock=args.no_exposure_lock,
                   visual_preset=None if args.visual_preset == "none" else args.visual_preset)
    for key, value in args.option:
        if key in options:
            p.error(f"--option {key}=...: use the flag --{key.replace('_', '-')}")
        options[key] = value
    run_service(lambda: CameraService(settings_from_args(args, **options)))
