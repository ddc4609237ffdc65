"""Error profiles: the real-world errors the twin injects, grouped as the paper's experiments saw them.

* ``ideal`` — no errors at all (the sensor keeps only its range limits and 1 mm quantisation).
* ``hand-turned`` — a person turns the object 30° ± 5° between views (achieved minus commanded turn
  ~ N(0, 2.5°) clipped to ±5°, set down within a few mm), the robot only moves the camera: hand-eye
  calibration error, joint encoder noise and D435 noise apply.
* ``realistic`` — what a real cell does to the camera and the scene on top of the hand-turned turns:
  every scan's camera pose off by 1–3 mm and 0.3–1° (backlash, link flex; drawn per scan), a hand-eye
  error of 3 mm / 0.5°, the object put down up to 3 cm from where it is expected, and the D435 model
  fitted to real RealSense frames (``D435Noise.calibrated()``, ``objscan bench sensor``). The benchmarks'
  default.
* ``harsh`` — ``realistic`` pushed to and beyond what the issue's held-out sets showed: every scan's camera
  pose off by 1–4 mm and 0.3–1.5° (so "about 3 mm / 1°" and beyond), turn scatter σ 4° clipped at ±8°, and
  set-down shifts of about 5 mm (σ 3.5 mm per axis, clipped at 8 mm); the rest as ``realistic``. The
  ``bench reconstruct`` harsh set (plain symmetric primitives) is recorded with it.
* ``robot-turned`` — the arm grasps, turns and sets the object down (paper, Sec. IV): achieved turns
  average 26–44° instead of 30° (a per-session gain on the commanded turn drawn from [26/30, 44/30]),
  per-turn scatter, occasional bounces that add a large extra turn and a cm-scale shift, mm-scale
  shifts on every set-down, the object pivoting in the gripper, and occasional slips.

Every number is a field of ``ErrorProfile``; ``get_profile(name, **overrides)`` selects and adjusts one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from math import erf

import numpy as np

from common.geometry import make_transform
from common.pose_accuracy import PoseAccuracy
from services.sim.errors import SimInputError
from services.sim.sensor_model import D435Noise


@dataclass(frozen=True)
class ErrorProfile:
    """All error sources of the twin. Angles in degrees, lengths in metres (``*_mm`` in mm)."""

    name: str = "custom"
    # camera pose as the robot believes it
    hand_eye_mm: float = 0.0  # fixed per session: |translation error| of the hand-eye calibration
    hand_eye_deg: float = 0.0  # fixed per session: rotation error angle of the hand-eye calibration
    joint_noise_deg: float = 0.0  # per-reading encoder noise (sigma) of each of the 6 joints
    joint_lever_m: float = 0.35  # lever arm that turns joint angle noise into camera position noise
    # per scan: |camera position error| (mm) and rotation error angle (deg), each uniform in its range,
    # random directions (backlash, link flex, repeatability: what joint noise alone underestimates)
    scan_pose_mm: tuple[float, float] = (0.0, 0.0)
    scan_pose_deg: tuple[float, float] = (0.0, 0.0)
    # the scene: the object stands up to this far (uniform over a disc) from where it is expected
    object_offset_m: float = 0.0
    # turning: achieved yaw change = gain * commanded + N(0, turn_sigma) (clipped) [+ bounce]
    turn_gain_range: tuple[float, float] = (1.0, 1.0)  # per-session gain drawn uniformly from this range
    turn_sigma_deg: float = 0.0
    turn_clip_deg: float | None = None  # clip of the per-turn scatter (not of the bounce)
    bounce_prob: float = 0.0  # chance per set-down that the object bounces / rotates on landing
    bounce_sigma_deg: float = 0.0
    bounce_shift_m: float = 0.0  # sigma of the extra xy shift of a bounce
    # set-down
    place_shift_sigma_m: float = 0.0  # per-axis xy shift of the footprint centre on every set-down
    place_shift_clip_m: float = 0.0  # clip of |shift| (0 = no clip), bounces included
    # grasp
    grasp_pivot_sigma_deg: float = 0.0  # the object pivots about the pad axis when the gripper closes
    grasp_shift_sigma_m: float = 0.0  # ...and slides along the approach and up directions
    slip_prob: float = 0.0  # chance that a geometrically sound grasp slips out anyway
    # the sensor
    camera: D435Noise = field(default_factory=D435Noise)

    def __post_init__(self) -> None:
        lo, hi = self.turn_gain_range
        bad = [f.name for f in fields(self) if _is_number(getattr(self, f.name))
               and not (np.isfinite(getattr(self, f.name)) and getattr(self, f.name) >= 0)]
        bad += [name for name in ("scan_pose_mm", "scan_pose_deg") if not _is_range(getattr(self, name))]
        if bad or lo <= 0 or hi < lo or not 0 <= self.slip_prob <= 1 or not 0 <= self.bounce_prob <= 1:
            raise SimInputError(f"error profile {self.name!r} has invalid values {bad or ''}".strip(),
                                code="bad_value", detail={"fields": bad})

    def to_dict(self) -> dict:
        """JSON-able form (for session.json and the sim's state)."""
        d = asdict(self)
        for name in _RANGES:
            d[name] = list(getattr(self, name))
        return d

    def pose_accuracy(self) -> PoseAccuracy:
        """The camera pose accuracy this profile's drawn errors amount to (one sigma of one camera pose), the
        twin's counterpart of a robot configuration's ``pose_accuracy``: the root mean square of the per-scan
        error sizes (uniform in their ranges), of the joint jitter (3 axes of ``sqrt(2) x joint_noise``, over the
        lever arm for position) and of the hand-eye error, added in quadrature."""
        def rms_uniform(lo_hi: tuple[float, float]) -> float:
            lo, hi = lo_hi
            return float(np.sqrt((lo * lo + lo * hi + hi * hi) / 3.0))

        jitter_deg = np.sqrt(3.0) * np.sqrt(2.0) * self.joint_noise_deg
        jitter_mm = np.radians(jitter_deg) * self.joint_lever_m * 1e3
        mm = np.sqrt(rms_uniform(self.scan_pose_mm) ** 2 + jitter_mm**2 + self.hand_eye_mm**2)
        deg = np.sqrt(rms_uniform(self.scan_pose_deg) ** 2 + jitter_deg**2 + self.hand_eye_deg**2)
        return PoseAccuracy(position_sigma_mm=round(float(mm), 3), orientation_sigma_deg=round(float(deg), 4))

    def turn_accuracy_deg(self, commanded_deg: float = 30.0) -> float:
        """One sigma of a turn's error (achieved minus commanded yaw, degrees) this profile draws, the twin's
        counterpart of what a turntable or an arm states, so the dynamic stage can tell a real turn error from a
        model whose views are stacked: the root mean square of the gain error on a ``commanded_deg`` turn
        (gain uniform in its range), of the clipped scatter, of the bounces (their chance times their spread)
        and of the grasp pivot, and the camera's own orientation error on the two views, added in quadrature."""
        lo, hi = ((g - 1.0) * commanded_deg for g in self.turn_gain_range)
        gain2 = (lo * lo + lo * hi + hi * hi) / 3.0
        s, clip = self.turn_sigma_deg, self.turn_clip_deg
        if s > 0 and clip is not None:  # variance of N(0, s) clipped to +-clip
            z = clip / s
            inside = s * s * (erf(z / np.sqrt(2.0)) - 2.0 * z * np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi))
            scatter2 = inside + clip * clip * (1.0 - erf(z / np.sqrt(2.0)))
        else:
            scatter2 = s * s
        bounce2 = self.bounce_prob * self.bounce_sigma_deg**2
        camera2 = 2.0 * self.pose_accuracy().orientation_sigma_deg ** 2
        return round(float(np.sqrt(gain2 + scatter2 + bounce2 + self.grasp_pivot_sigma_deg**2 + camera2)), 3)

    # -- draws ----------------------------------------------------------------------------------------
    def draw_hand_eye_error(self, rng: np.random.Generator) -> np.ndarray:
        """The session's hand-eye error E (camera frame): believed T_base_camera = true @ E.

        The translation has exactly ``hand_eye_mm`` and the rotation exactly ``hand_eye_deg``, in random
        directions, so the profile's numbers are the error's size.
        """
        t_dir = _unit(rng.standard_normal(3))
        r_axis = _unit(rng.standard_normal(3))
        from scipy.spatial.transform import Rotation

        R = Rotation.from_rotvec(r_axis * np.radians(self.hand_eye_deg)).as_matrix()
        return make_transform(R, t_dir * self.hand_eye_mm * 1e-3)

    def draw_joint_jitter(self, rng: np.random.Generator) -> np.ndarray:
        """Per-frame camera pose jitter from encoder noise (camera frame).

        Without kinematics we approximate: 6 joints' errors spread over 3 rotation axes give a per-axis
        rotation sigma of ``sqrt(2) * joint_noise``; the lever arm turns it into a position error.
        """
        if self.joint_noise_deg <= 0:
            return np.eye(4)
        from scipy.spatial.transform import Rotation

        s = np.sqrt(2.0) * np.radians(self.joint_noise_deg)
        rot = rng.normal(0.0, s, 3)
        trans = rng.normal(0.0, s * self.joint_lever_m, 3)
        return make_transform(Rotation.from_rotvec(rot).as_matrix(), trans)

    def draw_scan_pose_error(self, rng: np.random.Generator) -> np.ndarray:
        """One scan's camera pose error (camera frame): a translation of |t| ~ U(scan_pose_mm) and a rotation
        of angle ~ U(scan_pose_deg), in random directions. Identity, drawing nothing, when both are zero."""
        if not any(self.scan_pose_mm) and not any(self.scan_pose_deg):
            return np.eye(4)
        from scipy.spatial.transform import Rotation

        mm = rng.uniform(*self.scan_pose_mm)
        deg = rng.uniform(*self.scan_pose_deg)
        t = _unit(rng.standard_normal(3)) * mm * 1e-3
        R = Rotation.from_rotvec(_unit(rng.standard_normal(3)) * np.radians(deg)).as_matrix()
        return make_transform(R, t)

    def draw_frame_pose_error(self, rng: np.random.Generator) -> np.ndarray:
        """Everything that puts one frame's believed camera pose off besides the hand-eye error: joint
        encoder jitter, then the per-scan pose error."""
        return self.draw_joint_jitter(rng) @ self.draw_scan_pose_error(rng)

    def draw_object_offset(self, rng: np.random.Generator) -> np.ndarray:
        """The object's xy offset (m) from where it is expected: uniform over a disc of ``object_offset_m``."""
        if self.object_offset_m <= 0:
            return np.zeros(2)
        r = self.object_offset_m * np.sqrt(rng.random())
        a = rng.uniform(0.0, 2.0 * np.pi)
        return np.array([r * np.cos(a), r * np.sin(a)])

    def draw_turn_gain(self, rng: np.random.Generator) -> float:
        lo, hi = self.turn_gain_range
        return float(lo if hi == lo else rng.uniform(lo, hi))

    def draw_set_down(self, commanded_deg: float, gain: float,
                      rng: np.random.Generator) -> tuple[float, np.ndarray, bool]:
        """(achieved yaw change in degrees, xy shift in metres, bounced) for one set-down after a turn
        of ``commanded_deg``."""
        scatter = rng.normal(0.0, self.turn_sigma_deg) if self.turn_sigma_deg > 0 else 0.0
        if self.turn_clip_deg is not None:
            scatter = float(np.clip(scatter, -self.turn_clip_deg, self.turn_clip_deg))
        achieved = gain * commanded_deg + scatter
        shift = rng.normal(0.0, self.place_shift_sigma_m, 2) if self.place_shift_sigma_m > 0 else np.zeros(2)
        bounced = bool(self.bounce_prob > 0 and rng.random() < self.bounce_prob)
        if bounced:
            achieved += rng.normal(0.0, self.bounce_sigma_deg)
            shift = shift + rng.normal(0.0, self.bounce_shift_m, 2)
        norm = float(np.linalg.norm(shift))
        if self.place_shift_clip_m > 0 and norm > self.place_shift_clip_m:
            shift = shift * (self.place_shift_clip_m / norm)
        return float(achieved), shift, bounced


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


_RANGES = ("turn_gain_range", "scan_pose_mm", "scan_pose_deg")


def _is_range(v: object) -> bool:
    """A (lo, hi) pair of finite numbers with 0 <= lo <= hi."""
    return (isinstance(v, tuple) and len(v) == 2 and all(_is_number(x) and np.isfinite(x) for x in v)
            and 0 <= v[0] <= v[1])


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.array([1.0, 0.0, 0.0])


_HAND_EYE = {"hand_eye_mm": 2.0, "hand_eye_deg": 0.3, "joint_noise_deg": 0.05}

PROFILES: dict[str, ErrorProfile] = {
    "ideal": ErrorProfile(name="ideal", camera=D435Noise.noiseless()),
    "hand-turned": ErrorProfile(
        name="hand-turned", **_HAND_EYE,
        turn_sigma_deg=2.5, turn_clip_deg=5.0,
        place_shift_sigma_m=0.002, place_shift_clip_m=0.005,
    ),
    "realistic": ErrorProfile(
        name="realistic", hand_eye_mm=3.0, hand_eye_deg=0.5, joint_noise_deg=0.05,
        scan_pose_mm=(1.0, 3.0), scan_pose_deg=(0.3, 1.0), object_offset_m=0.03,
        turn_sigma_deg=2.5, turn_clip_deg=5.0,
        place_shift_sigma_m=0.002, place_shift_clip_m=0.005,
        camera=D435Noise.calibrated(),
    ),
    "harsh": ErrorProfile(
        name="harsh", hand_eye_mm=3.0, hand_eye_deg=0.5, joint_noise_deg=0.05,
        scan_pose_mm=(1.0, 4.0), scan_pose_deg=(0.3, 1.5), object_offset_m=0.03,
        turn_sigma_deg=4.0, turn_clip_deg=8.0,
        place_shift_sigma_m=0.0035, place_shift_clip_m=0.008,
        camera=D435Noise.calibrated(),
    ),
    "robot-turned": ErrorProfile(
        name="robot-turned", **_HAND_EYE,
        turn_gain_range=(26.0 / 30.0, 44.0 / 30.0), turn_sigma_deg=4.0, turn_clip_deg=12.0,
        bounce_prob=0.1, bounce_sigma_deg=12.0, bounce_shift_m=0.01,
        place_shift_sigma_m=0.003, place_shift_clip_m=0.03,
        grasp_pivot_sigma_deg=1.5, grasp_shift_sigma_m=0.001, slip_prob=0.07,
    ),
}


def profile_names() -> list[str]:
    return list(PROFILES)


def get_profile(name: str | ErrorProfile, **overrides) -> ErrorProfile:
    """The profile called ``name`` ("ideal", "hand-turned", "realistic", "harsh", "robot-turned"), with fields
    overridden.

    ``hand_turned``/``robot_turned`` spellings are accepted. Unknown names or fields raise
    ``SimInputError``.
    """
    if isinstance(name, ErrorProfile):
        base = name
    else:
        key = str(name).strip().lower().replace("_", "-")
        if key not in PROFILES:
            raise SimInputError(f"unknown error profile {name!r}; known: {', '.join(PROFILES)}",
                                code="unknown_profile", detail={"known": list(PROFILES)})
        base = PROFILES[key]
    if not overrides:
        return base
    known = {f.name for f in fields(ErrorProfile)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise SimInputError(f"unknown error profile fields {unknown}", code="bad_value", detail={"fields": unknown})
    for name in _RANGES:
        if isinstance(overrides.get(name), list):
            overrides[name] = tuple(overrides[name])
    return replace(base, **overrides)


def hand_turn(world, angle_deg: float, rng: np.random.Generator | None = None) -> float:
    """Turn the object on the table by ``angle_deg`` about the table normal through its centre, as a
    person would (no arm involved), with the world profile's turn and placement errors.

    Returns the achieved turn in degrees (ground truth). ``world`` is a ``services.sim.world.World``.
    """
    return world.turn_object(angle_deg, rng=rng)
