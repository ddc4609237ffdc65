"""A fixed camera watching an object turn on the table: the twin's stand-in for a turntable recording.

Why: ``objscan import`` takes real fixed-camera sequences whose truth nobody knows; rendering the same
kind of sequence from the twin gives one whose turns and intrinsics are known, so the importer's
estimates (turns, direction, the focal-length self-calibration) can be checked against the truth. The
folder written is the importer's folder layout (``rgb/``, ``depth/``, ``intrinsics.json``); the
intrinsics written may be deliberately wrong (``written_focal_scale``) to test the self-calibration.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from common.geometry import look_at
from common.messages import Intrinsics, d435_intrinsics
from services.sim.catalogue import load_object
from services.sim.errors import SimInputError
from services.sim.render import RenderScene, TableSpec, render
from services.sim.sensor_model import D435Noise
from services.sim.world import default_object_pose


@dataclass(frozen=True)
class TurntableSpec:
    """The recording: ``views`` frames, the object turned by ``step_deg`` between them (ccw > 0)."""

    object_name: str = "milk"
    views: int = 12
    step_deg: float = 30.0
    camera_distance: float = 0.42  # m, horizontal, from the object's axis
    camera_height: float = 0.16  # m above the table (a D4xx on a small tripod)
    noise: bool = True  # the D435 sensor model (realistic depth noise, dropouts, colour noise)
    seed: int = 0
    # a hand turn: each view's angle off ``step * k`` by a normal draw of this sigma (deg; view 0 stays at 0)
    turn_jitter_deg: float = 0.0
    width: int = 640
    height: int = 480

    def __post_init__(self) -> None:
        if self.views < 2 or not 0 < abs(self.step_deg) < 180:
            raise SimInputError("a turntable needs >= 2 views and a step in (0, 180) deg", code="bad_value",
                                detail={"views": self.views, "step_deg": self.step_deg})
        if not 0 <= self.turn_jitter_deg < abs(self.step_deg) / 2:
            raise SimInputError("turn_jitter_deg must be in [0, step / 2): the views must stay in turn order",
                                code="bad_value", detail={"turn_jitter_deg": self.turn_jitter_deg})
        if self.camera_distance <= 0.1 or self.camera_height <= 0:
            raise SimInputError("the camera must stand > 0.1 m away, above the table", code="bad_value")


def turn_angles(spec: TurntableSpec) -> list[float]:
    """Each view's angle (deg): ``step * k``, off by the hand-turn jitter (its own generator, so the sensor
    noise's draws are the same with and without it)."""
    rng = np.random.default_rng(spec.seed + 7907)
    jitter = rng.normal(0.0, spec.turn_jitter_deg, spec.views) if spec.turn_jitter_deg > 0 else np.zeros(spec.views)
    jitter[0] = 0.0
    return [float(spec.step_deg * k + jitter[k]) for k in range(spec.views)]


def turntable_frames(spec: TurntableSpec) -> tuple[Intrinsics, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Render the sequence: (intrinsics, T_base_camera, [(color, depth in mm)] per view)."""
    obj = load_object(spec.object_name)
    K = d435_intrinsics(spec.width, spec.height)
    centre = np.array([*default_object_pose()[:2, 3], 0.5 * float(obj.extent[2])])
    eye = centre + np.array([-spec.camera_distance, 0.0, spec.camera_height - centre[2]])
    T_base_camera = look_at(eye, centre)
    rng = np.random.default_rng(spec.seed)
    frames = []
    for yaw in turn_angles(spec):
        scene = RenderScene(obj, default_object_pose(yaw_deg=yaw), table=TableSpec())
        res = render(scene, T_base_camera, K, noise=D435Noise() if spec.noise else None, rng=rng)
        frames.append((res.color, res.depth))
    return K, T_base_camera, frames


def render_turntable(spec: TurntableSpec, out_dir: str | Path, written_focal_scale: float = 1.0) -> dict:
    """Render the sequence into ``out_dir`` (importer folder layout); returns the truth (intrinsics, camera
    pose, turns)."""
    out = Path(out_dir)
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    K, T_base_camera, frames = turntable_frames(spec)
    for k, (color, depth) in enumerate(frames):
        Image.fromarray(color).save(out / "rgb" / f"color_{k + 1}.png")
        Image.fromarray(depth).save(out / "depth" / f"depth_{k + 1}.png")
    written = {"fx": K.fx * written_focal_scale, "fy": K.fy * written_focal_scale, "cx": K.cx, "cy": K.cy}
    (out / "intrinsics.json").write_text(json.dumps(written))
    return {"intrinsics": K.as_dict(), "written_intrinsics": written, "T_base_camera": T_base_camera.tolist(),
            "turns_deg": turn_angles(spec)}
