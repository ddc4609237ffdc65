"""The hand-eye procedure on a live cell: move the arm through the calibration views, capture, detect,
solve, and measure the answer (against the twin's truth when the frames carry it).

It speaks to the cell only through the arm's ``move``/``state`` and the camera's ``capture``, so the same
code calibrates the twin and a real PAPRAS + D435. Views the arm cannot reach or where the board is not
seen are skipped and counted; the solve needs at least ``handeye.MIN_SAMPLES``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from common import keys
from common.api import CaptureRequest, MoveRequest
from common.client import request_sync
from common.errors import ObjscanError
from common.geometry import invert
from common.log import event
from common.messages import JointState, RGBDFrame
from services.calibration import handeye
from services.calibration.board import CharucoSpec, detect
from services.calibration.file import HandEyeCalibration
from services.calibration.handeye import mean_pose, pose_difference
from services.calibration.poses import calibration_views

log = logging.getLogger("objscan.calibration")


@dataclass
class ProcedureConfig:
    """How many views, around which board position, and how fast the arm moves between them."""

    views: int = 15
    board_xy: tuple[float, float] = (0.50, 0.0)
    board_height_m: float = CharucoSpec().thickness_m
    seed: int = 0
    speed_scale: float = 0.6
    width: int = 640
    height: int = 480

    def __post_init__(self) -> None:
        if not isinstance(self.views, int) or not 3 <= self.views <= 200:
            raise ValueError(f"views must be an integer in [3, 200], got {self.views!r}")
        if not all(np.isfinite(v) for v in self.board_xy) or not 0 < self.speed_scale <= 1:
            raise ValueError("board_xy must be finite and speed_scale in (0, 1]")


@dataclass
class ProcedureResult:
    """The calibration written to a file, plus the figures of the run (``figures`` is what --json prints)."""

    calibration: HandEyeCalibration
    figures: dict[str, Any] = field(default_factory=dict)


def _uncorrected(frame: RGBDFrame) -> np.ndarray:
    """The frame's pose as the cell stamps it without any calibration the camera service already applies."""
    T = np.asarray(frame.T_base_camera, dtype=np.float64)
    he = (frame.meta or {}).get("hand_eye")
    if isinstance(he, dict) and he.get("correction") is not None:
        T = T @ invert(np.asarray(he["correction"], dtype=np.float64))
    return T


def collect(session, robot: str, cfg: ProcedureConfig, spec: CharucoSpec,  # noqa: ANN001 - zenoh session
            ) -> tuple[list[handeye.Sample], list[RGBDFrame], list[np.ndarray], dict[str, int], np.ndarray]:
    """(samples, their frames, their T_base_gripper, skip counts, K) over the planned views."""
    center = np.array([cfg.board_xy[0], cfg.board_xy[1], cfg.board_height_m])
    samples, frames, grippers = [], [], []
    skipped = {"unreachable": 0, "board_not_seen": 0}
    K = None
    for i, T_cam in enumerate(calibration_views(center, cfg.views, cfg.seed)):
        try:
            request_sync(session, keys.arm(robot, "move"), MoveRequest(kind="pose", target=T_cam, frame="camera",
                                                                       speed_scale=cfg.speed_scale), timeout=120)
        except ObjscanError as exc:
            if exc.code in ("timeout", "unavailable", "estop"):
                raise
            skipped["unreachable"] += 1
            event(log, "calibration view skipped: arm cannot go there", view=i, code=exc.code)
            continue
        state = request_sync(session, keys.arm(robot, "state"), timeout=10)
        frame = request_sync(session, keys.camera_capture(robot), CaptureRequest(width=cfg.width, height=cfg.height),
                             timeout=60)
        assert isinstance(state, JointState) and isinstance(frame, RGBDFrame)
        K = frame.intrinsics.K
        det = detect(spec, frame.color, K)
        if det is None or state.T_base_gripper is None:
            skipped["board_not_seen"] += 1
            event(log, "calibration view skipped: board not seen", view=i)
            continue
        samples.append(handeye.Sample(np.asarray(state.T_base_gripper, np.float64), det.T_camera_board,
                                      det.ids, det.pixels))
        frames.append(frame)
        grippers.append(np.asarray(state.T_base_gripper, np.float64))
    return samples, frames, grippers, skipped, (np.eye(3) if K is None else K)


def run_procedure(session, robot: str, cfg: ProcedureConfig | None = None,  # noqa: ANN001 - zenoh session
                  spec: CharucoSpec | None = None) -> ProcedureResult:
    """Collect the views, solve, and compare nominal / calibrated mounts with the truth where known."""
    cfg = cfg or ProcedureConfig()
    spec = spec or CharucoSpec()
    t0 = time.perf_counter()
    samples, frames, grippers, skipped, K = collect(session, robot, cfg, spec)
    t_collect = time.perf_counter() - t0
    result = handeye.calibrate(samples, K, spec)
    nominal = mean_pose(np.stack([invert(G) @ _uncorrected(f) for G, f in zip(grippers, frames, strict=True)]))
    figures: dict[str, Any] = {
        "views_planned": cfg.views, "views_used": len(samples), "views_skipped": skipped,
        "seed_method": result.seed_method, "reprojection_px": result.reprojection_px,
        "board_spread_mm": result.board_spread_mm, "board_spread_deg": result.board_spread_deg,
        "methods": {m: {"reprojection_px": r.reprojection_px, "board_spread_mm": r.board_spread_mm,
                        "board_spread_deg": r.board_spread_deg} for m, r in result.methods.items()},
        "correction_mm": None, "correction_deg": None,
        "translation_error_mm": None, "rotation_error_deg": None, "ground_truth": False,
        "seconds": {"collect": round(t_collect, 2), "solve": round(time.perf_counter() - t0 - t_collect, 2)},
    }
    figures["correction_mm"], figures["correction_deg"] = pose_difference(result.T_gripper_camera, nominal)
    if all(f.T_base_camera_true is not None for f in frames):
        truth = mean_pose(np.stack([invert(G) @ np.asarray(f.T_base_camera_true, np.float64)
                                    for G, f in zip(grippers, frames, strict=True)]))
        figures["ground_truth"] = True
        figures["translation_error_mm"], figures["rotation_error_deg"] = pose_difference(result.T_gripper_camera,
                                                                                         truth)
        figures["nominal_translation_error_mm"], figures["nominal_rotation_error_deg"] = pose_difference(nominal,
                                                                                                         truth)
        for m, r in result.methods.items():
            figures["methods"][m]["translation_error_mm"], figures["methods"][m]["rotation_error_deg"] = \
                pose_difference(r.T_gripper_camera, truth)
    info = {k: figures[k] for k in ("views_used", "seed_method", "reprojection_px", "board_spread_mm",
                                    "board_spread_deg")}
    info.update(board=asdict(spec), created=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), robot=robot)
    cal = HandEyeCalibration(result.T_gripper_camera, nominal, info)
    return ProcedureResult(cal, figures)
