"""``objscan bench sensor``: the twin's D435 model against real RealSense frames, figure by figure.

Real: the 9 real 640x480 tabletop frames of ``../shared/data/rgbd/tabletop_uoc`` (RealSense D4xx, aligned
depth in mm); the GraspNet D435 frame (1280x720) is measured too and reported beside them, not fitted.
Twin: the HOPE objects on the twin's table, seen from 0.7-0.9 m at 40-55 deg elevation like the real
frames, rendered once without noise; each sensor model under test degrades the same perfect frames.

Every frame, real or twin, is measured by the same functions (``bench/sensor_metrics.py``):
table-plane residual (normalised to 1 m), edge dropouts and flying pixels per edge pixel, interior holes.
``fit_noise`` fits ``D435Noise`` to the real medians (subpixel noise, edge dropout and flying-pixel
chances, random dropouts; stereo occlusion on) and the result is compared with ``D435Noise.calibrated()``,
the model the ``realistic`` profile uses. Target: every twin figure within 25 % of the real one.
A PNG plot goes to ``docs/images/sensor_calibration.png``.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bench.sensor_metrics import FIGURES, DepthFigures, measure_depth, summarise

TOLERANCE = 0.25
PLOT = Path(__file__).resolve().parent.parent / "docs" / "images" / "sensor_calibration.png"


def _real_dir() -> Path:
    """``$OBJSCAN_RGBD_DIR`` or ``<repo>/../shared/data/rgbd`` (beside the HOPE objects)."""
    env = os.environ.get("OBJSCAN_RGBD_DIR")
    return Path(env) if env else Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "rgbd"


def real_frames() -> list[tuple[str, np.ndarray, tuple[float, float, float, float]]]:
    """(name, depth in metres, (fx, fy, cx, cy)) of the real 640x480 frames."""
    import cv2

    folder = _real_dir() / "tabletop_uoc"
    k = json.loads((folder / "camera_params.json").read_text())
    K = (k["fx"], k["fy"], k["x_offset"], k["y_offset"])
    return [(p.name, cv2.imread(str(p), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0, K)
            for p in sorted(folder.glob("*-depth.png"))]


def graspnet_frame() -> DepthFigures | None:
    """The GraspNet D435 frame's figures (1280x720), or None where the file is missing."""
    import cv2

    p = _real_dir() / "graspnet_realsense" / "depth.png"
    if not p.is_file():
        return None
    depth = cv2.imread(str(p), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    return measure_depth(depth, 631.549, 631.208, 638.435, 366.499)  # meta.mat intrinsic_matrix


def twin_scenes(quick: bool = False) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Perfect (depth, colour, fx) frames of the twin seen like the real frames."""
    from bench.scenario import camera_look_at
    from common.messages import d435_intrinsics
    from services.sim.catalogue import hope_names
    from services.sim.render import render
    from services.sim.world import World

    K = d435_intrinsics()
    out = []
    names = hope_names()[:2] if quick else hope_names()
    for name in names:
        world = World(name)
        centre = world.true_object_pose()[:3, 3] + np.array([0.0, 0.0, world.obj.height / 2])
        for dist, el, az in ((0.7, 45.0, 160.0), (0.8, 40.0, 200.0), (0.9, 55.0, 180.0)):
            e, a = np.radians(el), np.radians(az)
            eye = centre + dist * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            res = render(world.scene(), camera_look_at(eye, centre), K, noise=None)
            out.append((res.depth_true, res.color, K.fx))
    return out


def measure_twin(scenes, noise, seed: int = 0) -> list[DepthFigures]:
    """Figures of the twin's frames degraded by ``noise`` (a ``D435Noise``), quantised to 1 mm as a D435 is."""
    from common.messages import d435_intrinsics
    from services.sim.sensor_model import apply_d435_noise

    K = d435_intrinsics()
    figs = []
    for k, (depth_true, color, fx) in enumerate(scenes):
        depth, _ = apply_d435_noise(depth_true, color, fx, noise, np.random.default_rng(seed + k))
        depth = np.rint(depth * 1000.0) / 1000.0
        figs.append(measure_depth(depth.astype(np.float32), K.fx, K.fy, K.cx, K.cy))
    return figs


KNOBS = {"plane_sigma_1m_mm": "subpixel", "edge_dropout_per_edge": "edge_dropout_prob",
         "flying_per_edge": "flying_pixel_prob", "interior_hole_fraction": "dropout_prob"}


def fit_noise(real: dict[str, float], scenes, base=None, rounds: int = 3) -> Any:
    """``D435Noise`` whose twin figures match ``real`` (medians).

    Each knob drives one figure nearly alone (``KNOBS``: subpixel -> plane sigma, edge dropout chance ->
    edge dropouts on top of the stereo occlusion band that geometry fixes, flying chance -> flying pixels,
    random dropout chance -> interior holes), nearly linearly: figure = floor + slope x knob. The floor is
    measured with every knob at 0 (quantisation, the occlusion band), the slope from the current model;
    each round solves for the knob that hits the real figure, kept inside the model's valid range.
    """
    from services.sim.sensor_model import D435Noise

    noise = base or D435Noise(stereo_occlusion=True)
    floor = summarise(measure_twin(scenes, replace(noise, **{k: 0.0 for k in KNOBS.values()})))
    for _ in range(rounds):
        twin = summarise(measure_twin(scenes, noise))
        new = {}
        for fig, knob in KNOBS.items():
            value = getattr(noise, knob)
            slope = (twin[fig] - floor[fig]) / value if value > 0 else 0.0
            new[knob] = (real[fig] - floor[fig]) / slope if slope > 0 else value
        fly = float(np.clip(new["flying_pixel_prob"], 0.0, 0.9))
        noise = replace(noise, subpixel=round(float(np.clip(new["subpixel"], 0.0, 1.0)), 4),
                        flying_pixel_prob=round(fly, 3),
                        edge_dropout_prob=round(float(np.clip(new["edge_dropout_prob"], 0.0, 1.0 - fly)), 3),
                        dropout_prob=round(float(np.clip(new["dropout_prob"], 0.0, 0.05)), 5))
    return noise


def _within(twin: dict[str, float], real: dict[str, float]) -> dict[str, float]:
    return {f: round(twin[f] / real[f] - 1.0, 3) for f in FIGURES}


def plot(real_per_frame: list[DepthFigures], rows: dict[str, dict[str, float]], path: Path = PLOT) -> Path:
    """A bar chart (OpenCV, no plotting dependency): each figure relative to the real median (= 1), real
    frames as dots, the +-25 % band shaded."""
    import cv2

    real = rows["real"]
    W, H, left, top, bottom = 960, 420, 60, 50, 90
    img = np.full((H, W, 3), 255, np.uint8)
    ymax = 3.0
    y = lambda v: int(top + (H - top - bottom) * (1 - min(v, ymax) / ymax))  # noqa: E731
    cv2.rectangle(img, (left, y(1 + TOLERANCE)), (W - 10, y(1 - TOLERANCE)), (220, 235, 220), -1)
    for v in (0, 1, 2, 3):
        cv2.line(img, (left, y(v)), (W - 10, y(v)), (200, 200, 200), 1)
        cv2.putText(img, f"{v}x", (15, y(v) + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (80, 80, 80), 1)
    colours = {"real": (60, 60, 60), "twin_default": (40, 40, 220), "twin_calibrated": (200, 120, 30)}
    group = (W - left - 20) // len(FIGURES)
    for i, f in enumerate(FIGURES):
        x0 = left + i * group + 20
        for j, (name, col) in enumerate(colours.items()):
            v = rows[name][f] / real[f]
            cv2.rectangle(img, (x0 + j * 50, y(v)), (x0 + j * 50 + 40, y(0)), col, -1)
            cv2.putText(img, f"{v:.2f}", (x0 + j * 50, y(v) - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4, col, 1)
        for fr in real_per_frame:
            cv2.circle(img, (x0 + 20, y(getattr(fr, f) / real[f])), 3, (0, 0, 0), -1)
        cv2.putText(img, f.replace("_", " ")[:24], (x0 - 10, H - bottom + 25), cv2.FONT_HERSHEY_SIMPLEX, 0.42,
                    (0, 0, 0), 1)
    cv2.putText(img, "D435 model vs real RealSense frames (real median = 1; dots: real frames; band: +-25%)",
                (left, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
    for j, (name, col) in enumerate(colours.items()):
        cv2.rectangle(img, (left + j * 200, H - 30), (left + j * 200 + 14, H - 16), col, -1)
        cv2.putText(img, name, (left + j * 200 + 20, H - 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)
    return path


def run(quick: bool = False) -> dict[str, Any]:
    """Measure real and twin frames, fit, compare; returns the JSON figures (and writes the plot)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from services.sim.sensor_model import D435Noise

    real_per_frame = [measure_depth(d, *K) for _, d, K in real_frames()]
    real = summarise(real_per_frame)
    scenes = twin_scenes(quick)
    default = summarise(measure_twin(scenes, D435Noise()))
    calibrated_noise = D435Noise.calibrated()
    calibrated = summarise(measure_twin(scenes, calibrated_noise, seed=100))  # other draws than the fit's
    fitted_noise = fit_noise(real, scenes, rounds=2 if quick else 4)
    rows = {"real": real, "twin_default": default, "twin_calibrated": calibrated}
    rel = _within(calibrated, real)
    gn = graspnet_frame()
    out: dict[str, Any] = {
        "real": {k: round(v, 5) for k, v in real.items()},
        "twin_default": {k: round(v, 5) for k, v in default.items()},
        "twin_calibrated": {k: round(v, 5) for k, v in calibrated.items()},
        "calibrated_minus_real_rel": rel,
        "default_minus_real_rel": _within(default, real),
        "calibrated_within_25pct": all(abs(v) <= TOLERANCE for v in rel.values()),
        "calibrated_model": {k: getattr(calibrated_noise, k) for k in (*KNOBS.values(), "stereo_occlusion")},
        "refit_now": {k: getattr(fitted_noise, k) for k in KNOBS.values()},
        "real_frames": len(real_per_frame),
        "twin_frames": len(scenes),
        "real_per_frame": [{k: round(v, 4) for k, v in f.as_dict().items()} for f in real_per_frame],
        "graspnet_d435_1280x720": {k: round(v, 4) for k, v in gn.as_dict().items()} if gn else None,
    }
    out["plot"] = str(plot(real_per_frame, rows))
    return out


def main() -> None:
    import sys

    from bench.report import print_figures

    print_figures("sensor", run(quick="--quick" in sys.argv))


if __name__ == "__main__":
    main()
