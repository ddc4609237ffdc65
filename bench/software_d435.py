"""A D435 emulated with pyrealsense2's ``software_device``: unaligned depth + color you inject yourself.

Why: CI and most desks have no camera. Injecting known depth and color through librealsense's own
software device lets the real backend code (pipeline, ``rs.align``, filters, intrinsics, depth scale) run
against ground truth, and ``record_db3`` turns injected frames into a ``.db3`` recording that the backend
plays back like one taken on the robot.

Verified with pyrealsense2 2.59.1:
- the pipeline accepts the device through ``pipeline.set_device(dev)``; ``dev.add_to(ctx)`` does not make it
  visible to ``ctx.query_devices()`` (0 devices), so a pipeline cannot find it by serial;
- frame numbers must start at 1: a recording whose first frame is numbered 0 plays back with that frame
  missing and the last depth frame renumbered;
- ``depth_units`` must be registered as a read-only option on the depth sensor for
  ``first_depth_sensor().get_depth_scale()`` to work, and is also stamped on every depth frame.
- options added with ``add_option`` read back their *minimum* until set, so defaults are set explicitly;
  ``rs.option_range(min, max, step, default)`` stores step and default swapped, so its fields are assigned;
  ``set_metadata`` on a software sensor stamps that metadata on the frames pushed after it.

Camera controls are emulated (``SoftwareD435Spec.emulate_controls``): the color sensor offers auto
exposure / exposure / gain / auto white balance / white balance, the depth sensor a visual preset. While
auto exposure is on, the exposure drifts from frame to frame (as a real auto loop hunts) and, with
``exposure_scales_color``, the injected color is scaled by it; each frame carries the exposure, gain and
white balance in force as metadata.
``stall()`` stops frames from coming through (a USB drop) until ``resume()``.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.messages import Intrinsics
from services.camera.errors import BadFrameError, CameraConfigError, CameraError, CaptureTimeout
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.realsense.camera import _rs

D435_DEPTH_PRESETS: dict[tuple[int, int], tuple[float, float, float, float]] = {
    (640, 480): (383.0, 383.0, 320.0, 240.0),
    (848, 480): (424.0, 424.0, 424.0, 240.0),
}
"""(width, height) -> (fx, fy, cx, cy) of the D435 depth (left IR) camera: wider field of view than color."""

D435_DEPTH_TO_COLOR_TRANSLATION_M = (0.015, 0.0, 0.0)
"""Translation of the depth -> color extrinsics a D435 typically reports (p_color = p_depth + t), m."""

D435_DEPTH_SCALE = 0.001
"""Metres per depth unit of a D435 at its default setting."""


def d435_depth_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """Typical D435 depth-imager intrinsics for a supported size (a fresh object each call)."""
    try:
        fx, fy, cx, cy = D435_DEPTH_PRESETS[(int(width), int(height))]
    except KeyError:
        sizes = ", ".join(f"{w}x{h}" for w, h in D435_DEPTH_PRESETS)
        raise CameraConfigError(f"no D435 depth preset for {width}x{height}; known: {sizes}",
                                detail={"width": width, "height": height}) from None
    return Intrinsics(width=int(width), height=int(height), fx=fx, fy=fy, cx=cx, cy=cy)


def d435_T_color_depth() -> np.ndarray:
    """Typical extrinsics ``T_color_depth`` (depth frame -> color frame) of a D435: a pure translation."""
    T = np.eye(4)
    T[:3, 3] = D435_DEPTH_TO_COLOR_TRANSLATION_M
    return T


FramePair = tuple[np.ndarray, np.ndarray]
"""(depth uint16 HxW in depth units, color uint8 HxWx3 RGB)."""


@dataclass
class SoftwareD435Spec:
    """What the emulated camera reports: per-stream intrinsics, depth->color extrinsics, depth scale."""

    color_intrinsics: Intrinsics = field(default_factory=d435_color_intrinsics)
    depth_intrinsics: Intrinsics = field(default_factory=d435_depth_intrinsics)
    T_color_depth: np.ndarray = field(default_factory=d435_T_color_depth)
    depth_scale: float = D435_DEPTH_SCALE
    fps: int = 30
    serial: str = "000000000000"
    name: str = "Intel RealSense D435 (software)"
    emulate_controls: bool = True
    nominal_exposure_us: float = 156.0
    exposure_scales_color: bool = False  # injected color x (exposure / nominal): shows what drifting AE does


def _rs_intrinsics(rs: Any, intr: Intrinsics) -> Any:
    out = rs.intrinsics()
    out.width, out.height = intr.width, intr.height
    out.fx, out.fy, out.ppx, out.ppy = intr.fx, intr.fy, intr.cx, intr.cy
    out.model = rs.distortion.none
    out.coeffs = [0.0] * 5
    return out


class SoftwareD435:
    """An emulated D435: give ``device`` to ``RealSenseCamera(device=...)``; ``push`` injects a frame pair."""

    def __init__(self, spec: SoftwareD435Spec | None = None):
        rs = _rs()
        self.spec = spec or SoftwareD435Spec()
        s = self.spec
        self._lock = threading.Lock()
        self._frame_number = 0
        dev = rs.software_device()
        dev.register_info(rs.camera_info.name, s.name)
        dev.register_info(rs.camera_info.serial_number, s.serial)
        dev.register_info(rs.camera_info.product_line, "D400")
        self._depth_sensor = dev.add_sensor("Stereo Module")
        self._color_sensor = dev.add_sensor("RGB Camera")
        self._depth_profile = self._add_stream(rs, self._depth_sensor, rs.stream.depth, rs.format.z16, 2,
                                               s.depth_intrinsics, uid=1)
        self._color_profile = self._add_stream(rs, self._color_sensor, rs.stream.color, rs.format.rgb8, 3,
                                               s.color_intrinsics, uid=2)
        self._depth_sensor.add_read_only_option(rs.option.depth_units, float(s.depth_scale))
        ext = rs.extrinsics()
        T = np.asarray(s.T_color_depth, dtype=np.float64)
        ext.rotation = [float(v) for v in T[:3, :3].T.reshape(-1)]  # librealsense stores it column-major
        ext.translation = [float(v) for v in T[:3, 3]]
        self._depth_profile.register_extrinsics_to(self._color_profile, ext)
        dev.create_matcher(rs.matchers.dlr_c)  # pair depth and color by frame number, like a D400
        self.device = dev
        self._stalled = threading.Event()
        if s.emulate_controls:
            self._add_controls(rs)

    def _add_controls(self, rs: Any) -> None:
        o = rs.option
        for sensor, opt, lo, hi, step, default in (
                (self._color_sensor, o.enable_auto_exposure, 0, 1, 1, 1),
                (self._color_sensor, o.exposure, 1, 10000, 1, self.spec.nominal_exposure_us),
                (self._color_sensor, o.gain, 0, 128, 1, 64),
                (self._color_sensor, o.enable_auto_white_balance, 0, 1, 1, 1),
                (self._color_sensor, o.white_balance, 2800, 6500, 10, 4600),
                (self._depth_sensor, o.visual_preset, 0, 6, 1, 0)):
            rng = rs.option_range()  # attributes, not the constructor: 2.59 swaps its step and default
            rng.min, rng.max, rng.step, rng.default = float(lo), float(hi), float(step), float(default)
            sensor.add_option(opt, rng, True)
            sensor.set_option(opt, float(default))

    def controls(self) -> tuple[float, float, float]:
        """(exposure us, gain, white balance K) in force for the next frame: drifting while auto is on."""
        rs = _rs()
        cs, o = self._color_sensor, rs.option
        n = self._frame_number
        if cs.get_option(o.enable_auto_exposure) > 0.5:
            exposure = self.spec.nominal_exposure_us * (1.0 + 0.3 * np.sin(n / 4.0))
        else:
            exposure = cs.get_option(o.exposure)
        wb = 4600.0 + 400.0 * np.sin(n / 6.0) if cs.get_option(o.enable_auto_white_balance) > 0.5 \
            else cs.get_option(o.white_balance)
        return float(round(exposure)), float(cs.get_option(o.gain)), float(round(wb / 10) * 10)

    def stall(self) -> None:
        """Frames stop coming through, as when the camera drops off USB."""
        self._stalled.set()

    def resume(self) -> None:
        self._stalled.clear()

    def _add_stream(self, rs: Any, sensor: Any, kind: Any, fmt: Any, bpp: int, intr: Intrinsics,
                    uid: int) -> Any:
        vs = rs.video_stream()
        vs.type, vs.fmt, vs.bpp = kind, fmt, bpp
        vs.width, vs.height, vs.fps = intr.width, intr.height, self.spec.fps
        vs.index, vs.uid = 0, uid
        vs.intrinsics = _rs_intrinsics(rs, intr)
        return sensor.add_video_stream(vs, True)

    def push(self, depth: np.ndarray, color: np.ndarray) -> int:
        """Inject one depth/color pair (same frame number and timestamp); returns the frame number."""
        rs = _rs()
        di, ci = self.spec.depth_intrinsics, self.spec.color_intrinsics
        depth = np.ascontiguousarray(depth)
        color = np.ascontiguousarray(color)
        if depth.dtype != np.uint16 or depth.shape != (di.height, di.width):
            raise BadFrameError("injected depth must be uint16 of the depth stream's size",
                                detail={"shape": list(depth.shape), "dtype": str(depth.dtype)})
        if color.dtype != np.uint8 or color.shape != (ci.height, ci.width, 3):
            raise BadFrameError("injected color must be uint8 HxWx3 of the color stream's size",
                                detail={"shape": list(color.shape), "dtype": str(color.dtype)})
        with self._lock:
            if self._stalled.is_set():
                return self._frame_number
            self._frame_number += 1  # starts at 1: see the module notes
            n = self._frame_number
            if self.spec.emulate_controls:
                exposure, gain, wb = self.controls()
                md = rs.frame_metadata_value
                for key, value in ((md.actual_exposure, exposure), (md.gain_level, gain), (md.white_balance, wb)):
                    self._color_sensor.set_metadata(key, int(value))
                gain_factor = exposure / self.spec.nominal_exposure_us
                if self.spec.exposure_scales_color and abs(gain_factor - 1.0) > 1e-9:
                    color = np.clip(color * gain_factor + 0.5, 0, 255).astype(np.uint8)
            stamp_ms = n * 1000.0 / self.spec.fps
            for sensor, profile, pixels, bpp in ((self._depth_sensor, self._depth_profile, depth, 2),
                                                 (self._color_sensor, self._color_profile, color, 3)):
                f = rs.software_video_frame()
                f.pixels = pixels
                f.stride = pixels.shape[1] * bpp
                f.bpp = bpp
                f.timestamp = stamp_ms
                f.domain = rs.timestamp_domain.hardware_clock
                f.frame_number = n
                f.profile = profile.as_video_stream_profile()
                if bpp == 2:
                    f.depth_units = float(self.spec.depth_scale)
                sensor.on_video_frame(f)
        return n

    @contextlib.contextmanager
    def streaming(self, source: FramePair | Callable[[int], FramePair]) -> Iterator[SoftwareD435]:
        """Push frames at ``fps`` from a background thread while the block runs, like a live camera.

        ``source`` is one fixed pair or a callable ``i -> pair`` (e.g. adding fresh noise each frame).
        """
        stop = threading.Event()
        errors: list[BaseException] = []

        def run() -> None:
            i = 0
            while not stop.is_set():
                try:
                    pair = source(i) if callable(source) else source
                    self.push(*pair)
                except BaseException as exc:  # surfaced when the block exits
                    errors.append(exc)
                    return
                i += 1
                stop.wait(1.0 / self.spec.fps)

        thread = threading.Thread(target=run, name="software-d435", daemon=True)
        thread.start()
        try:
            yield self
        finally:
            stop.set()
            thread.join(timeout=5.0)
        if errors:
            raise errors[0]


def record_db3(path: str | Path, frames: Iterable[FramePair], spec: SoftwareD435Spec | None = None,
               timeout_ms: int = 2000) -> Path:
    """Record injected frame pairs to a rosbag2 ``.db3`` file that ``RealSenseCamera`` can play back.

    Each pair is pushed and then awaited, so every pair becomes exactly one recorded frameset.
    """
    rs = _rs()
    path = Path(path)
    if path.suffix != ".db3":
        raise CameraError("librealsense 2.59 records only rosbag2 files: the name must end in .db3",
                          code="bad_config", detail={"path": str(path)})
    path.parent.mkdir(parents=True, exist_ok=True)
    cam = SoftwareD435(spec)
    s = cam.spec
    pipeline = rs.pipeline(rs.context())
    pipeline.set_device(cam.device)
    cfg = rs.config()
    di, ci = s.depth_intrinsics, s.color_intrinsics
    cfg.enable_stream(rs.stream.depth, di.width, di.height, rs.format.z16, s.fps)
    cfg.enable_stream(rs.stream.color, ci.width, ci.height, rs.format.rgb8, s.fps)
    cfg.enable_record_to_file(str(path))
    pipeline.start(cfg)
    try:
        for depth, color in frames:
            n = cam.push(depth, color)
            ok, fs = pipeline.try_wait_for_frames(timeout_ms)
            if not ok:
                raise CaptureTimeout(f"recording frame {n} did not come through the pipeline")
    finally:
        pipeline.stop()
    return path
