"""What one acquisition is asked to do, with defaults that work on the simulated cell."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any


@dataclass
class ScanGeometry:
    """How the 3 scan poses of a view are placed around the object (replacing the paper's fixed poses).

    The camera looks at the object's mid-height from ``distance`` at ``elevation_deg`` above the table,
    from the arm's side, at the azimuth offsets given. Candidates are tried in order until the arm can
    reach all three (checked by IK + collision dry runs).
    """

    azimuth_offsets_deg: tuple[float, ...] = (0.0, 22.0, -22.0)
    distances: tuple[float, ...] = (0.38, 0.42, 0.34)
    elevations_deg: tuple[float, ...] = (45.0, 55.0, 38.0)
    look_distance: float = 0.45  # the locate pose: higher and farther, to see the table around the object
    look_elevation_deg: float = 55.0


@dataclass
class TurnMotion:
    """The pick-turn-place sequence (paper II-B): lift, turn about the table normal, set down, retreat."""

    lift: float = 0.02  # m above the grasp before turning
    clearance: float = 0.08  # m above the object's top for joint-space moves near it
    speed_scale: float = 0.6
    approach_speed_scale: float = 0.3
    gripper_force: float = 30.0
    open_margin: float = 0.04  # opening beyond the planned width (partial views underestimate it)
    object_box_margin: float = 0.01
    # joint configurations the IK of the first pose of a pick-turn-place is also started from (besides the
    # arm's current one, and each solution's other wrist branch): the arm's home posture has both wrist
    # rolls mid-range, so its branch leaves room to turn either way
    branch_seeds: tuple[tuple[float, ...], ...] = ((0.0, -0.3, -0.9, 0.0, 1.2, 0.0),)
    max_checks: int = 48  # pick-turn-place chains dry-run per turn (each is a few cheap planning requests)


@dataclass
class AcquisitionConfig:
    """One acquisition: which object, how many views, which error profile and seed (sim), which profiles."""

    object: str = "milk"
    views: int = 12
    turn_deg: float = 30.0
    profile: str = "robot-turned"
    seed: int = 0
    width: int = 640
    height: int = 480
    static_profile: str = "default"
    dynamic_config: dict = field(default_factory=dict)
    max_grasp_attempts: int = 16  # executions tried per turn before re-scanning (dry-run failures do not count)
    max_rescans: int = 2  # re-scans per view before the session ends with a reason
    force_first_slip: bool = False  # sim: the first grasp slips (recovery test)
    evaluate: bool = True  # compare with ground truth when the cell knows it (sim)
    # pair registrations during the acquisition (services/orchestrator/incremental.py); off: all at the end
    incremental: bool = True
    workspace_center: tuple[float, float] = (0.60, 0.0)  # where the locate pose looks (and the twin puts the object)
    scan: ScanGeometry = field(default_factory=ScanGeometry)
    turn: TurnMotion = field(default_factory=TurnMotion)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> AcquisitionConfig:
        known = {f.name for f in fields(cls)}
        kwargs = {k: v for k, v in data.items() if k in known and k not in ("scan", "turn")}
        cfg = cls(**kwargs)
        if isinstance(data.get("scan"), dict):
            cfg.scan = ScanGeometry(**{k: tuple(v) if isinstance(v, list) else v for k, v in data["scan"].items()})
        if isinstance(data.get("turn"), dict):
            turn = dict(data["turn"])
            if "branch_seeds" in turn:  # JSON has lists where the dataclass has tuples
                turn["branch_seeds"] = tuple(tuple(float(x) for x in q) for q in turn["branch_seeds"])
            cfg.turn = TurnMotion(**{k: v for k, v in turn.items() if k in {f.name for f in fields(TurnMotion)}})
        return cfg
