"""Typed errors of the grasp planner; each has a stable ``code`` a caller can branch on."""

from __future__ import annotations

from common.errors import InvalidRequest, ObjscanError


class GraspInputError(InvalidRequest):
    """The cloud, normals or table plane handed to the planner are unusable (empty, NaN, wrong shape).

    ``code`` is specific: ``empty_cloud``, ``bad_shape``, ``non_finite``, ``missing_normals``,
    ``zero_normals``, ``bad_table``.
    """

    code = "invalid_grasp_input"


class GraspConfigError(ObjscanError):
    """A planner or gripper configuration value is out of range."""

    code = "bad_grasp_config"
