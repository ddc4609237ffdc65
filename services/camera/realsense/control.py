"""Camera control of a D435: visual preset, exposure and white balance locked for a whole acquisition.

Why lock: with auto exposure and auto white balance on, each of the 12 views is exposed differently and
colour ICP then compares colours that differ for reasons that are not the object. So the camera settles
on the first frames (auto on, ``warmup_frames``), the settled values are read (from the frames' metadata
where the kernel provides it, else from the sensor's options), auto is switched off and those values are
written back as manual settings. Every frame's ``meta["exposure"]`` records what was in force.

The depth sensor gets a visual preset (``high_accuracy`` by default: fewer, better depth points, what a
model wants). Options a device does not offer are skipped and listed, never guessed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: Names of ``rs.rs400_visual_preset`` accepted in the config.
VISUAL_PRESETS = ("custom", "default", "hand", "high_accuracy", "high_density", "medium_density")


@dataclass
class ExposureState:
    """What the color sensor runs with; ``locked`` once auto exposure/white balance are off."""

    exposure_us: float | None = None
    gain: float | None = None
    white_balance_k: float | None = None
    locked: bool = False
    source: str = "none"  # "metadata" | "option" | "none"
    skipped: list[str] = field(default_factory=list)

    def as_meta(self) -> dict[str, Any]:
        return {"exposure_us": self.exposure_us, "gain": self.gain, "white_balance_k": self.white_balance_k,
                "locked": self.locked, "source": self.source}


def sensor_for(rs: Any, device: Any, stream: Any) -> Any | None:
    """The device's sensor that produces ``stream`` (works for software devices, unlike first_color_sensor)."""
    for sensor in device.query_sensors():
        try:
            if any(p.stream_type() == stream for p in sensor.get_stream_profiles()):
                return sensor
        except RuntimeError:  # a sensor without profiles (e.g. a motion module on some firmwares)
            continue
    return None


def apply_visual_preset(rs: Any, device: Any, preset: str | None) -> str | None:
    """Set the depth sensor's visual preset; returns the preset set, None when skipped or unsupported."""
    if preset is None:
        return None
    sensor = sensor_for(rs, device, rs.stream.depth)
    if sensor is None or not sensor.supports(rs.option.visual_preset):
        return None
    sensor.set_option(rs.option.visual_preset, float(int(getattr(rs.rs400_visual_preset, preset))))
    return preset


def frame_metadata(frame: Any, key: Any) -> float | None:
    """A frame's metadata value, or None where the device/kernel does not provide it."""
    try:
        if frame is not None and frame.supports_frame_metadata(key):
            return float(frame.get_frame_metadata(key))
    except RuntimeError:
        return None
    return None


def _option(rs: Any, sensor: Any, opt: Any) -> float | None:
    try:
        return float(sensor.get_option(opt)) if sensor.supports(opt) else None
    except RuntimeError:
        return None


def settled_values(rs: Any, sensor: Any, color_frame: Any) -> ExposureState:
    """Exposure, gain and white balance the auto loops settled on: frame metadata first, options otherwise."""
    md = rs.frame_metadata_value
    st = ExposureState(source="metadata")
    st.exposure_us = frame_metadata(color_frame, md.actual_exposure)
    st.gain = frame_metadata(color_frame, md.gain_level)
    st.white_balance_k = frame_metadata(color_frame, md.white_balance)
    if st.exposure_us is None or st.white_balance_k is None:
        st.source = "option"
    if st.exposure_us is None:
        st.exposure_us = _option(rs, sensor, rs.option.exposure)
    if st.gain is None:
        st.gain = _option(rs, sensor, rs.option.gain)
    if st.white_balance_k is None:
        st.white_balance_k = _option(rs, sensor, rs.option.white_balance)
    if st.exposure_us is None and st.white_balance_k is None:
        st.source = "none"
    return st


def lock_exposure(rs: Any, device: Any, color_frame: Any) -> ExposureState:
    """Switch auto exposure and auto white balance off, holding the values they settled on."""
    sensor = sensor_for(rs, device, rs.stream.color)
    if sensor is None:
        return ExposureState(skipped=["color sensor"])
    return apply_exposure(rs, device, settled_values(rs, sensor, color_frame))


def apply_exposure(rs: Any, device: Any, wanted: ExposureState) -> ExposureState:
    """Auto exposure / white balance off and ``wanted``'s values written (clamped to the sensor's range);
    used at start and again after a reconnect, so the whole acquisition keeps one exposure."""
    sensor = sensor_for(rs, device, rs.stream.color)
    st = ExposureState(wanted.exposure_us, wanted.gain, wanted.white_balance_k, source=wanted.source)
    if sensor is None:
        st.skipped.append("color sensor")
        return st
    o = rs.option
    for auto, manual, attr in ((o.enable_auto_exposure, o.exposure, "exposure_us"), (None, o.gain, "gain"),
                               (o.enable_auto_white_balance, o.white_balance, "white_balance_k")):
        value = getattr(st, attr)
        if auto is not None:
            if sensor.supports(auto):
                sensor.set_option(auto, 0.0)
            else:
                st.skipped.append(str(auto))
        if value is not None and sensor.supports(manual):
            rng = sensor.get_option_range(manual)
            v = min(max(value, rng.min), rng.max)
            if rng.step > 0:
                v = rng.min + round((v - rng.min) / rng.step) * rng.step
            sensor.set_option(manual, float(v))
            setattr(st, attr, float(v))
        elif value is not None:
            st.skipped.append(str(manual))
    st.locked = not any("auto" in s for s in st.skipped)
    return st
