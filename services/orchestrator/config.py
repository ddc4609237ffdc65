"""What one acquisition is asked to do, with defaults that work on the simulated cell.

Every field is validated when a config is made (``__post_init__``) and ``from_dict`` refuses unknown keys:
a config arrives over the network in the orchestrator's ``run`` request (and from ``objscan scan --config``),
and an unchecked ``views: 3.5`` or NaN would leave the session ``running`` forever, ``views: 100000000`` would
block the orchestrator's event loop. A bad value raises ``ConfigError`` (code ``invalid_config``) naming the
field; ``workspace_center`` must be within the arm's reach (``services/arm/workspace.py``).
"""

from __future__ import annotations

import math
import typing
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from common.errors import InvalidRequest
from common.pose_accuracy import PoseAccuracy, PoseAccuracyError
from services.arm.workspace import TABLE_RADIUS_M, table_reach_problem

UP_AXES = ("x", "y", "z", "-x", "-y", "-z")
"""A mesh's upright axis as the twin takes it (``services/sim/catalogue.py``)."""


class ConfigError(InvalidRequest):
    """An acquisition config field has a wrong type or a value out of range; ``detail.field`` names it."""

    code = "invalid_config"


def _fail(name: str, why: str, value: Any) -> ConfigError:
    return ConfigError(f"config field {name!r} {why}, got {value!r}"[:300], detail={"field": name})


def _number(name: str, value: Any, lo: float, hi: float, *, integer: bool = False, lo_open: bool = False) -> None:
    """``value`` is a finite number (an int when ``integer``) in [lo, hi] (or (lo, hi] when ``lo_open``)."""
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        raise _fail(name, "must be an integer" if integer else "must be a number", value)
    if not math.isfinite(value):
        raise _fail(name, "must be finite", value)
    if value > hi or value < lo or (lo_open and value == lo):
        raise _fail(name, f"must be in {'(' if lo_open else '['}{lo}, {hi}]", value)


def _numbers(name: str, value: Any, lo: float, hi: float, *, length: int | None = None, min_len: int = 1,
             max_len: int = 64) -> tuple[float, ...]:
    """A tuple of finite numbers in [lo, hi] (lists from JSON become tuples)."""
    if not isinstance(value, (list, tuple)):
        raise _fail(name, "must be a list of numbers", value)
    if (length is not None and len(value) != length) or not min_len <= len(value) <= max_len:
        raise _fail(name, f"must hold {length if length is not None else f'{min_len}-{max_len}'} numbers", value)
    for i, v in enumerate(value):
        _number(f"{name}[{i}]", v, lo, hi)
    return tuple(float(v) for v in value)


def _text(name: str, value: Any, max_len: int = 512) -> None:
    if not isinstance(value, str) or not value or len(value) > max_len or "\x00" in value:
        raise _fail(name, f"must be a non-empty string of at most {max_len} characters", value)


def _flag(name: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise _fail(name, "must be true or false", value)


def _known_keys(cls: type, data: Any, where: str) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise _fail(where, "must be a map", data)
    known = {f.name for f in fields(cls)}
    unknown = sorted(str(k) for k in data if k not in known)
    if unknown:
        raise ConfigError(f"unknown {where} key(s) {unknown[:5]}; known: {sorted(known)}",
                          detail={"field": where, "unknown": unknown[:20]})
    return data


def _plain(value: Any) -> Any:
    """Tuples as lists, all the way down (``yaml.safe_dump`` and JSON write lists only)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


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

    def __post_init__(self) -> None:
        self.azimuth_offsets_deg = _numbers("scan.azimuth_offsets_deg", self.azimuth_offsets_deg, -180.0, 180.0)
        self.distances = _numbers("scan.distances", self.distances, 0.05, 2.0)
        self.elevations_deg = _numbers("scan.elevations_deg", self.elevations_deg, -90.0, 90.0)
        _number("scan.look_distance", self.look_distance, 0.05, 2.0)
        _number("scan.look_elevation_deg", self.look_elevation_deg, -90.0, 90.0)


@dataclass
class RelocationConfig:
    """Where a relocated set-down may put the object (``services/orchestrator/regrasp.py``): spots at
    ``near_radius`` from the arm's base (and at the object's own distance when farther, up to
    ``max_radius``) at the azimuths ``azimuths_deg`` about the base."""

    enabled: bool = True
    near_radius: float = 0.40  # a thin box standing on edge turns from every yaw at 0.38-0.42 m (regrasp.py)
    max_radius: float = 0.40  # spots also at the object's own distance when it stands farther, up to this
    azimuths_deg: tuple[float, ...] = (0.0, 30.0, -30.0)
    max_checks: int = 40  # relocated chains dry-run per turn, on top of ``TurnMotion.max_checks``
    min_shift: float = 0.02  # m: a spot nearer than this to the object is where it already stands
    reposition: bool = True  # bring an object that drifted off the favoured spots back (reposition.py)
    reposition_drift: float = 0.08  # m from every favoured spot before the object is brought back
    max_repositions: int = 1  # per view: a spot that cannot be turned from after one is not chased further

    def __post_init__(self) -> None:
        _flag("turn.relocation.enabled", self.enabled)
        lo, hi = TABLE_RADIUS_M
        _number("turn.relocation.near_radius", self.near_radius, lo, hi)
        _number("turn.relocation.max_radius", self.max_radius, self.near_radius, hi)
        self.azimuths_deg = tuple(_numbers("turn.relocation.azimuths_deg", self.azimuths_deg, -90.0, 90.0))
        _number("turn.relocation.max_checks", self.max_checks, 1, 1000, integer=True)
        _number("turn.relocation.min_shift", self.min_shift, 0.0, 0.5)
        _flag("turn.relocation.reposition", self.reposition)
        _number("turn.relocation.reposition_drift", self.reposition_drift, 0.0, 1.0)
        _number("turn.relocation.max_repositions", self.max_repositions, 0, 10, integer=True)


@dataclass
class TurnMotion:
    """The pick-turn-place sequence (paper II-B): lift, turn about the table normal, set down, retreat."""

    lift: float = 0.02  # m above the grasp before turning
    clearance: float = 0.08  # m above the object's top for joint-space moves near it
    # m: the same for a top-down pick's chains tried after all others. The PAPRAS wrist pointing down reaches no
    # higher than about 0.16-0.18 m at 0.35-0.45 m from the base, so ``clearance`` above a 10 cm object leaves
    # it out of reach there; the arm checks every joint-space move against the object's box all the same
    low_clearance: float = 0.04
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
    relocation: RelocationConfig = field(default_factory=RelocationConfig)  # regrasp: set down elsewhere

    def __post_init__(self) -> None:
        if isinstance(self.relocation, dict):
            self.relocation = RelocationConfig(**_known_keys(RelocationConfig, self.relocation, "turn.relocation"))
        if not isinstance(self.relocation, RelocationConfig):
            raise _fail("turn.relocation", "must be a map", self.relocation)
        for name, hi in (("lift", 0.5), ("clearance", 1.0), ("low_clearance", 1.0), ("open_margin", 0.2),
                         ("object_box_margin", 0.2)):
            _number(f"turn.{name}", getattr(self, name), 0.0, hi)
        for name in ("speed_scale", "approach_speed_scale"):
            _number(f"turn.{name}", getattr(self, name), 0.0, 1.0, lo_open=True)
        _number("turn.gripper_force", self.gripper_force, 0.0, 200.0, lo_open=True)
        _number("turn.max_checks", self.max_checks, 1, 1000, integer=True)
        if not isinstance(self.branch_seeds, (list, tuple)) or len(self.branch_seeds) > 16:
            raise _fail("turn.branch_seeds", "must be a list of at most 16 joint configurations", self.branch_seeds)
        self.branch_seeds = tuple(_numbers(f"turn.branch_seeds[{i}]", q, -2 * math.pi, 2 * math.pi, length=6)
                                  for i, q in enumerate(self.branch_seeds))


@dataclass
class AcquisitionConfig:
    """One acquisition: which object, how many views, which error profile and seed (sim), which profiles."""

    object: str = "milk"
    views: int = 12
    turn_deg: float = 30.0
    profile: str = "robot-turned"
    physics: str = "geometric"  # sim: "mujoco" (contact physics) or "geometric" (fast checker); the CLI picks mujoco
    seed: int = 0
    width: int = 640
    height: int = 480
    static_profile: str = "default"
    dynamic_config: dict = field(default_factory=dict)
    max_grasp_attempts: int = 16  # executions tried per turn before re-scanning (dry-run failures do not count)
    max_rescans: int = 2  # re-scans per view before the session ends with a reason
    # the arm's camera pose accuracy {"position_sigma_mm", "orientation_sigma_deg"} sent with every static
    # registration (a scan correction it cannot explain is not fused) and stored in session.json; empty: the
    # cell states it at start (the twin from its error profile, a real arm from its robot configuration)
    pose_accuracy: dict = field(default_factory=dict)
    # how well the cell turns the object (1 sigma per turn, degrees; 0: not stated); the twin states it from its
    # error profile, session.json keeps it, and reconstruct's turn check reads it from there
    turn_accuracy_deg: float = 0.0
    force_first_slip: bool = False  # sim: the first grasp slips (recovery test)
    # a view whose object height differs from the previous one's by more than max(m, rel * height) means the
    # object toppled at the set-down: the views restart from where it lies, at most this many times
    topple_height_tol_m: float = 0.02
    topple_height_rel: float = 0.25
    max_topple_restarts: int = 1
    # an object no pick reaches turned on the table by a push, at most this often (push.py). A push turns a box
    # 35-50 degrees; one whose only grasp is tied to its yaw crosses the wrist's unreachable band (about 80 degrees
    # at 0.60 m) twice in twelve views, two pushes each, besides those that first bring it into reach
    max_pushes: int = 8
    evaluate: bool = True  # compare with ground truth when the cell knows it (sim)
    # pair registrations during the acquisition (services/orchestrator/incremental.py); off: all at the end
    incremental: bool = True
    workspace_center: tuple[float, float] = (0.60, 0.0)  # where the locate pose looks (and the twin puts the object)
    # the object's mesh as the twin loads it: its file units in metres (0.001 for millimetres) and its upright
    # axis ("y", "-z", ...); None: the file's own (HOPE: 0.01 and y; any other mesh: 1 and z)
    object_scale: float | None = None
    object_up_axis: str | None = None
    scan: ScanGeometry = field(default_factory=ScanGeometry)
    turn: TurnMotion = field(default_factory=TurnMotion)

    MAX_VIEWS: typing.ClassVar[int] = 72  # 5 degrees apart; the paper takes 12

    def __post_init__(self) -> None:
        _text("object", self.object, 4096)
        _number("views", self.views, 1, self.MAX_VIEWS, integer=True)
        _number("turn_deg", self.turn_deg, 0.0, 180.0, lo_open=True)
        _text("profile", self.profile, 64)
        _text("static_profile", self.static_profile, 64)
        _number("seed", self.seed, 0, 2**32 - 1, integer=True)
        _number("width", self.width, 16, 4096, integer=True)
        _number("height", self.height, 16, 4096, integer=True)
        if not isinstance(self.dynamic_config, dict):
            raise _fail("dynamic_config", "must be a map", self.dynamic_config)
        _number("max_grasp_attempts", self.max_grasp_attempts, 1, 1000, integer=True)
        _number("max_rescans", self.max_rescans, 0, 100, integer=True)
        _number("max_pushes", self.max_pushes, 0, 10, integer=True)
        if not isinstance(self.pose_accuracy, dict):
            raise _fail("pose_accuracy", "must be a map", self.pose_accuracy)
        if self.pose_accuracy:
            try:
                PoseAccuracy.from_dict(self.pose_accuracy)
            except PoseAccuracyError as exc:
                raise _fail("pose_accuracy", exc.message, self.pose_accuracy) from exc
        _number("turn_accuracy_deg", self.turn_accuracy_deg, 0.0, 180.0)
        _flag("force_first_slip", self.force_first_slip)
        _flag("evaluate", self.evaluate)
        x, y = _numbers("workspace_center", self.workspace_center, -2.0, 2.0, length=2)
        self.workspace_center = (x, y)
        why = table_reach_problem(x, y)
        if why is not None:
            raise _fail("workspace_center", f"is out of the arm's reach ({why})", [x, y])
        if self.object_scale is not None:
            _number("object_scale", self.object_scale, 0.0, 1000.0, lo_open=True)
        if self.object_up_axis is not None and self.object_up_axis not in UP_AXES:
            raise _fail("object_up_axis", f"must be one of {', '.join(UP_AXES)}", self.object_up_axis)
        if not isinstance(self.scan, ScanGeometry):
            raise _fail("scan", "must be a ScanGeometry", self.scan)
        if not isinstance(self.turn, TurnMotion):
            raise _fail("turn", "must be a TurnMotion", self.turn)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON/YAML values (lists, not tuples): what ``from_dict`` and ``objscan scan --config`` read."""
        return _plain(asdict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> AcquisitionConfig:
        """A validated config from a JSON map (a ``run`` request's or a journal's); raises ``ConfigError``."""
        data = _known_keys(cls, data, "config")
        kwargs = {k: v for k, v in data.items() if k not in ("scan", "turn")}
        try:
            if "scan" in data:
                kwargs["scan"] = ScanGeometry(**_known_keys(ScanGeometry, data["scan"], "scan"))
            if "turn" in data:
                kwargs["turn"] = TurnMotion(**_known_keys(TurnMotion, data["turn"], "turn"))
            return cls(**kwargs)
        except TypeError as exc:  # cannot happen with known keys, but never let a request crash the handler
            raise ConfigError(f"bad config: {exc}", detail={"field": "config"}) from None
