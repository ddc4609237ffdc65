"""Grasp planning (paper II-B): GeoGrasp-style frontal and top-down antipodal grasps, collision
filtering against the table and the object, and the named poses the arm executes to turn the object.

The service face (``service.py``) calls :func:`plan_grasps` / :func:`plan_grasps_for_cloud` and sends
``GraspPlan.to_messages()`` back.
"""

from services.grasp.config import GraspPlannerConfig, GripperConfig
from services.grasp.errors import GraspConfigError, GraspInputError
from services.grasp.planner import plan_grasps, plan_grasps_for_cloud, validate_inputs
from services.grasp.result import REASONS, GraspPlan, PlannedGrasp, Rejections

__all__ = [
    "REASONS",
    "GraspConfigError",
    "GraspInputError",
    "GraspPlan",
    "GraspPlannerConfig",
    "GripperConfig",
    "PlannedGrasp",
    "Rejections",
    "plan_grasps",
    "plan_grasps_for_cloud",
    "validate_inputs",
]
