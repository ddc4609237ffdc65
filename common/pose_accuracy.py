"""How well the arm knows where its camera is: the pose accuracy a registration may trust its prior to.

The robot configuration states it (PAPRAS: ``pose_accuracy`` in ``services/arm/robot/papras_dynamixel.yaml``;
the twin: derived from each error profile's drawn errors), the acquisition carries it to the static
registration in every ``StaticRequest`` and stores it in ``session.json``, and offline ``reconstruct`` /
``import`` read it back from there. A scan correction the stated accuracy cannot explain (beyond a multiple of
these sigmas) is rejected however well it fits: no arm is 90 degrees or 40 cm off its commanded pose, but a
symmetric box fits itself turned by 90 degrees (docs/static-registration.md, "Plausibility").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from common.errors import ObjscanError

#: session.json / robot-configuration key of the accuracy
POSE_ACCURACY_KEY = "pose_accuracy"


class PoseAccuracyError(ObjscanError):
    """A stated pose accuracy is not two finite, non-negative sigmas."""

    code = "bad_pose_accuracy"


@dataclass(frozen=True)
class PoseAccuracy:
    """One standard deviation of the camera pose error as the arm believes it: the size of the position
    error (mm) and the angle of the orientation error (degrees), of one camera pose."""

    position_sigma_mm: float
    orientation_sigma_deg: float

    def __post_init__(self) -> None:
        for name in ("position_sigma_mm", "orientation_sigma_deg"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
                raise PoseAccuracyError(f"{POSE_ACCURACY_KEY}.{name} must be a finite number >= 0, got {v!r}",
                                        detail={"key": f"{POSE_ACCURACY_KEY}.{name}", "got": repr(v)})

    def to_dict(self) -> dict[str, float]:
        return {"position_sigma_mm": float(self.position_sigma_mm),
                "orientation_sigma_deg": float(self.orientation_sigma_deg)}

    @classmethod
    def from_dict(cls, data: Any, source: str = POSE_ACCURACY_KEY) -> PoseAccuracy:
        """From ``{"position_sigma_mm": ..., "orientation_sigma_deg": ...}``; anything else is a typed error."""
        if not isinstance(data, dict):
            raise PoseAccuracyError(f"{source}: expected a mapping with position_sigma_mm and orientation_sigma_deg",
                                    detail={"key": source, "got": type(data).__name__})
        allowed = {"position_sigma_mm", "orientation_sigma_deg"}
        unknown, missing = sorted(set(data) - allowed), sorted(allowed - set(data))
        if unknown or missing:
            raise PoseAccuracyError(f"{source}: unknown key(s) {unknown}, missing {missing}",
                                    detail={"key": source, "unknown": unknown, "missing": missing})
        return cls(position_sigma_mm=data["position_sigma_mm"], orientation_sigma_deg=data["orientation_sigma_deg"])


#: Assumed when nothing states the arm's accuracy (a session recorded before it was stored, an imported
#: sequence): a little worse than a hobby-grade 6-DOF arm with a wrist camera (3 mm / 1 deg per scan), so a
#: right correction is never rejected, while 90 degrees or 40 cm still are (bound ~34 mm / ~7 deg at 5 sigma).
CONSERVATIVE = PoseAccuracy(position_sigma_mm=4.0, orientation_sigma_deg=1.0)


def session_pose_accuracy(session_data: dict[str, Any]) -> tuple[PoseAccuracy, str]:
    """The accuracy a stored session states (top level of ``session.json``, else its acquisition
    ``config``), and where it came from (``"session"`` or ``"default"``: ``CONSERVATIVE``)."""
    for holder in (session_data, session_data.get("config") or {}):
        if isinstance(holder, dict) and holder.get(POSE_ACCURACY_KEY):  # {}: the acquisition stated none
            return PoseAccuracy.from_dict(holder[POSE_ACCURACY_KEY]), "session"
    return CONSERVATIVE, "default"
