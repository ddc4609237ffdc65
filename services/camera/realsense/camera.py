"""The D435 backend: a pyrealsense2 pipeline with depth aligned to color.

One code path serves three sources, so the tests exercise what runs on the robot:
- a live camera found over USB (optionally by serial number);
- a ``.db3`` recording played back non-real-time (``config.playback_file``);
- an injected ``rs.device``, e.g. the software D435 of ``bench/software_d435.py`` (pyrealsense2's ``software_device``
  handed to the pipeline with ``pipeline.set_device``; ``software_device.add_to(context)`` does not make it
  visible to ``query_devices`` in pyrealsense2 2.59, so the context route is not used).

Per capture: drop frames queued while the arm was moving (live only), pull ``frames_per_capture`` fresh
framesets through the optional spatial/temporal filters, align depth to color with
``rs.align(rs.stream.color)``, and copy both images out of librealsense's frame pool. Intrinsics and depth
scale come from the device, never from a preset.

Live cameras also get the depth visual preset and an exposure/white balance locked after the warm-up
(``control.py``), and survive a USB drop: after ``timeouts_before_reset`` consecutive frame timeouts the
device is ``hardware_reset`` and the pipeline restarted with the same locked exposure.
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.messages import Intrinsics, RGBDFrame
from services.camera.base import Camera, stamp_pose
from services.camera.errors import (
    BadFrameError,
    CameraError,
    CaptureTimeout,
    EndOfReplay,
    NoDeviceError,
    ReplayDataError,
)
from services.camera.realsense.config import RealSenseCameraConfig
from services.camera.realsense.control import (
    ExposureState,
    apply_exposure,
    apply_visual_preset,
    frame_metadata,
    lock_exposure,
)

PLAYBACK_SUFFIXES = (".db3", ".bag")
_POLL_MS = 50


def _rs() -> Any:
    """Import pyrealsense2 on first use, so the other backends never pay for (or need) it."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:  # pragma: no cover - it is a project dependency
        raise CameraError(f"pyrealsense2 is not installed: {exc}", code="missing_dependency") from None
    return rs


def to_rgb(image: np.ndarray, fmt: Any) -> np.ndarray:
    """Convert a color frame's pixels to RGB uint8 HxWx3 (recordings may hold bgr8/rgba8/bgra8)."""
    rs = _rs()
    if fmt == rs.format.rgb8:
        return image
    if fmt == rs.format.bgr8:
        return image[..., ::-1]
    if fmt == rs.format.rgba8:
        return image[..., :3]
    if fmt == rs.format.bgra8:
        return image[..., 2::-1]
    raise BadFrameError(f"unsupported color format {fmt}; record color as rgb8 or bgr8")


def float32_value(x: float) -> float:
    """librealsense keeps depth units as float32 (0.001 reads 0.0010000000475); recover the decimal value."""
    return float(f"{float(x):.7g}")


def intrinsics_from_rs(intr: Any) -> Intrinsics:
    """Our pinhole ``Intrinsics`` from an ``rs.intrinsics`` (distortion goes to frame meta).

    librealsense stores them as float32; the decimal value is recovered so 615.0 stays 615.0.
    """
    return Intrinsics(width=int(intr.width), height=int(intr.height), fx=float32_value(intr.fx),
                      fy=float32_value(intr.fy), cx=float32_value(intr.ppx), cy=float32_value(intr.ppy))


def choose_serial(attached: list[str], wanted: str | None) -> str:
    """The serial to open: ``wanted`` when attached; the only camera when none is wanted; else a clear error."""
    if wanted is not None:
        if wanted not in attached:
            raise NoDeviceError(f"no RealSense camera with serial {wanted} is attached",
                                detail={"attached": attached})
        return wanted
    if len(attached) > 1:
        raise NoDeviceError(f"{len(attached)} RealSense cameras are attached ({', '.join(attached)}): choose one "
                            "with --serial (camera service) or OBJSCAN_CAMERA_SERIAL", code="ambiguous_camera",
                            detail={"attached": attached})
    return attached[0]


class RealSenseCamera(Camera):
    """A D435 through pyrealsense2 (live, playback, or an injected device such as a software D435)."""

    config: RealSenseCameraConfig
    pose_from_arm = True

    def __init__(self, config: RealSenseCameraConfig | None = None, *, device: Any = None):
        """``device``: an ``rs.device`` to stream from instead of searching USB (tests, emulation)."""
        super().__init__(config or RealSenseCameraConfig())
        self._device_in = device
        self._pipeline: Any = None
        self._align: Any = None
        self._spatial: Any = None
        self._playback: Any = None
        self._depth_scale = 0.0
        self._device_info: dict[str, Any] = {}
        self._device: Any = None
        self._exposure: ExposureState | None = None
        self._preset: str | None = None
        self.reconnects = 0

    # ------------------------------------------------------------------------------------------ open
    def _open(self) -> None:
        rs = _rs()
        cfg = rs.config()
        ctx = rs.context()
        pipeline = rs.pipeline(ctx)
        if self.config.playback_file is not None:
            pipeline.set_device(self._load_playback(ctx, Path(self.config.playback_file)))
            cfg.enable_stream(rs.stream.depth)
            cfg.enable_stream(rs.stream.color)
        else:
            if self._device_in is not None:
                pipeline.set_device(self._device_in)
            else:
                cfg.enable_device(self._find_serial(rs))
            w, h, fps = self.config.width, self.config.height, self.config.fps
            cfg.enable_stream(rs.stream.depth, w, h, rs.format.z16, fps)
            cfg.enable_stream(rs.stream.color, w, h, rs.format.rgb8, fps)
        try:
            profile = pipeline.start(cfg)
        except RuntimeError as exc:
            self._playback = None
            if self.config.playback_file is not None:
                raise ReplayDataError(f"cannot play back {self.config.playback_file}: {exc}",
                                      detail={"file": str(self.config.playback_file)}) from None
            mode = f"{self.config.width}x{self.config.height}@{self.config.fps}"
            raise CameraError(f"cannot start the RealSense pipeline at {mode}: {exc}",
                              code="start_failed") from None
        self._pipeline = pipeline
        try:
            device = profile.get_device()
            try:
                self._depth_scale = float32_value(device.first_depth_sensor().get_depth_scale())
            except RuntimeError as exc:
                raise CameraError(f"the device has no depth sensor with a depth scale: {exc}",
                                  code="no_depth") from None
            self._device_info = self._describe(rs, device, profile)
            self._device = device
            self._align = rs.align(rs.stream.color)
            self._spatial = rs.spatial_filter() if self.config.spatial_filter else None
            if self.config.playback_file is None:
                self._preset = apply_visual_preset(rs, device, self.config.visual_preset)
                if self._exposure is not None and self._exposure.locked:  # reconnected: keep the run's exposure
                    self._exposure = apply_exposure(rs, device, self._exposure)
                frames = None
                for _ in range(self.config.warmup_frames):
                    frames = self._wait_frames(reconnect=False)
                if self.config.lock_exposure and (self._exposure is None or not self._exposure.locked):
                    self._exposure = lock_exposure(rs, device, frames.get_color_frame() if frames else None)
        except BaseException:
            self._stop_pipeline()
            raise

    def _load_playback(self, ctx: Any, path: Path) -> Any:
        """Open a recording as a non-real-time playback device *before* the pipeline starts.

        Switching to non-real-time after ``pipeline.start`` (or using ``enable_device_from_file``) lets
        the first frames play in real time, and the pipeline's one-frame queue then drops whatever a slow
        reader has not taken: measured, 1 to 2 of 3 recorded frames lost at random. Loaded like this,
        playback waits for the reader and every frame is served once, in order.
        """
        if not path.is_file():
            raise ReplayDataError(f"playback file {path} does not exist", detail={"file": str(path)})
        if path.suffix.lower() not in PLAYBACK_SUFFIXES:
            raise ReplayDataError(f"playback file {path} is not a RealSense recording (.db3 or .bag)",
                                  detail={"file": str(path)})
        try:
            device = ctx.load_device(str(path))
            self._playback = device.as_playback()
            self._playback.set_real_time(False)
        except RuntimeError as exc:
            self._playback = None
            raise ReplayDataError(f"cannot play back {path}: {exc}", detail={"file": str(path)}) from None
        return device

    def _find_serial(self, rs: Any) -> str:
        devices = rs.context().query_devices()
        serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
        if not serials:
            raise NoDeviceError(
                "no RealSense camera is attached: plug the D435 into a USB 3 port and make sure the udev "
                "rules are installed (docs/camera.md); to run without one use the sim or replay backend, "
                "or set playback_file")
        # a reconnect reopens the same camera even when no serial was configured
        return choose_serial(serials, self.config.serial or self._device_info.get("serial"))

    def _describe(self, rs: Any, device: Any, profile: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        ci = rs.camera_info
        for key, info in (("name", ci.name), ("serial", ci.serial_number),
                          ("firmware", ci.firmware_version), ("usb", ci.usb_type_descriptor)):
            if device.supports(info):
                out[key] = device.get_info(info)
        streams = {}
        for stream in profile.get_streams():
            vsp = stream.as_video_stream_profile()
            streams[stream.stream_name().lower() or str(stream.stream_type())] = {
                "width": vsp.width(), "height": vsp.height(), "fps": stream.fps(),
                "format": str(stream.format())}
        out["streams"] = streams
        return out

    # ------------------------------------------------------------------------------------------ grab
    def _wait_frames(self, reconnect: bool = True) -> Any:
        """Next frameset; ``end_of_replay`` when a playback has run out, ``timeout`` otherwise.

        A live camera that times out ``timeouts_before_reset`` times in a row is reset and reopened once
        (``reconnect``) before the timeout is reported.
        """
        n = self.config.timeouts_before_reset
        if not reconnect or self._playback is not None or n == 0:
            return self._wait_once()
        for attempt in range(n + 1):
            try:
                return self._wait_once()
            except CaptureTimeout:
                if attempt == n:
                    raise
                if attempt == n - 1:
                    self._reconnect()
        raise AssertionError("unreachable")  # pragma: no cover

    def _hardware_reset(self, device: Any) -> None:
        """Power-cycle the camera over USB (it re-enumerates within a few seconds)."""
        device.hardware_reset()

    def _reconnect(self) -> None:
        """hardware_reset the device, then restart the pipeline with the same settings and exposure."""
        device = self._device
        self._stop_pipeline()
        if device is not None:
            try:
                self._hardware_reset(device)
            except RuntimeError:  # a device that cannot reset (playback, software): restarting is all we can do
                pass
        self.reconnects += 1
        for attempt in range(3):  # the camera re-enumerates on USB within a few seconds of the reset
            time.sleep(self.config.reset_wait_s)
            try:
                self._open()
                return
            except NoDeviceError:
                if attempt == 2:
                    raise

    def _wait_once(self) -> Any:
        rs = _rs()
        deadline = time.monotonic() + self.config.timeout_ms / 1000.0
        while True:
            ok, frames = self._pipeline.try_wait_for_frames(_POLL_MS)
            if ok:
                return frames
            if self._playback is not None and self._playback.current_status() == rs.playback_status.stopped:
                frames = self._pipeline.poll_for_frames()
                if frames:
                    return frames
                raise EndOfReplay(f"playback of {self.config.playback_file} has no more frames",
                                  detail={"file": str(self.config.playback_file)})
            if time.monotonic() > deadline:
                raise CaptureTimeout(f"no frame from the RealSense camera within {self.config.timeout_ms} ms",
                                     detail={"timeout_ms": self.config.timeout_ms})

    def skip_frame(self) -> None:
        """Read past one capture's framesets without filtering, aligning or copying them: a recording read one
        frame in N (``objscan import --every``) pays only for the frames it keeps. ``EndOfReplay`` at the end
        of a playback, like ``capture``; the skipped frame takes no sequence number."""
        with self._lock:
            self._before_capture(None)
            for _ in range(self.config.frames_per_capture):
                self._wait_frames(reconnect=False)

    def _grab(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        rs = _rs()
        if self._playback is None:
            while self._pipeline.poll_for_frames():  # stale frames queued while the arm was still moving
                pass
        temporal = rs.temporal_filter() if self.config.temporal_filter else None  # fresh history per pose
        frames = None
        for _ in range(self.config.frames_per_capture):
            frames = self._wait_frames()
            if self._spatial is not None:
                frames = self._spatial.process(frames).as_frameset()
            if temporal is not None:
                frames = temporal.process(frames).as_frameset()
        aligned = self._align.process(frames)
        depth_f, color_f = aligned.get_depth_frame(), aligned.get_color_frame()
        if not depth_f or not color_f:
            raise BadFrameError("the RealSense frameset lacks a depth or a color frame")
        depth = np.array(np.asanyarray(depth_f.get_data()), dtype=np.uint16, copy=True)
        color = np.ascontiguousarray(to_rgb(np.asanyarray(color_f.get_data()), color_f.profile.format()),
                                     dtype=np.uint8).copy()
        rs_intr = color_f.profile.as_video_stream_profile().get_intrinsics()
        units = float32_value(depth_f.get_units()) if hasattr(depth_f, "get_units") else 0.0
        meta: dict[str, Any] = {
            "device_timestamp_ms": float(color_f.get_timestamp()),
            "timestamp_domain": str(color_f.get_frame_timestamp_domain()),
            "frame_number": int(color_f.get_frame_number()),
            "distortion": {"model": str(rs_intr.model), "coeffs": [float(c) for c in rs_intr.coeffs]},
            "filters": [name for name, on in (("spatial", self._spatial is not None),
                                               ("temporal", temporal is not None)) if on],
            "source": "playback" if self._playback is not None else "live",
        }
        if "serial" in self._device_info:
            meta["serial"] = self._device_info["serial"]
        if self._playback is None:
            meta["visual_preset"] = self._preset
            md = rs.frame_metadata_value
            meta["exposure"] = {**(self._exposure or ExposureState()).as_meta(),
                                "frame_exposure_us": frame_metadata(color_f, md.actual_exposure),
                                "frame_white_balance_k": frame_metadata(color_f, md.white_balance)}
            meta["reconnects"] = self.reconnects
        T = stamp_pose(meta, T_base_camera)
        stamp = float(color_f.get_timestamp()) / 1000.0 if self._playback is not None else time.time()
        return RGBDFrame(color=color, depth=depth, depth_scale=units if units > 0 else self._depth_scale,
                         intrinsics=intrinsics_from_rs(rs_intr), T_base_camera=T, stamp=stamp,
                         seq=self._next_seq(), meta=meta)

    # ------------------------------------------------------------------------------------------ close
    def _stop_pipeline(self) -> None:
        if self._pipeline is not None:
            with contextlib.suppress(RuntimeError):  # already stopped (e.g. the device was unplugged)
                self._pipeline.stop()
        self._pipeline = None
        self._playback = None

    def _close(self) -> None:
        self._stop_pipeline()

    def _info(self) -> dict[str, Any]:
        out: dict[str, Any] = {"depth_scale": self._depth_scale, **self._device_info, "reconnects": self.reconnects,
                               "visual_preset": self._preset,
                               "exposure": None if self._exposure is None else self._exposure.as_meta()}
        if self.config.playback_file is not None:
            out["playback_file"] = str(self.config.playback_file)
        return out
