"""The registration library's one public module: everything outside ``services/registration`` calls this.

Why one module: the same pipeline serves a live scan (the registration service, ``service.py`` and
``dynamic_face.py`` on top of this module), the incremental model of an acquisition, a replay, ``objscan
reconstruct``, ``objscan import``, the report, export, library and every benchmark. With one entry point they
all run the same steps with the same definitions (a view's centre, the dynamic stage's config from a map,
the static stage's config from a profile), and registration's internals can change without touching them.
No Zenoh here: the service face is the only Zenoh-aware part of registration.

What it offers, by job:

- **static stage** (one view's scans -> the isolated object in ``base``): ``register_scans``,
  ``register_view``, ``static_config``, ``StaticConfig``, ``StaticViewResult``, their errors, and
  ``view_result`` (the wire form the service answers with);
- **views** (the dynamic stage's input): ``DynamicView``, ``view_from_static`` (in-process results),
  ``view_from_result`` / ``views_from_results`` (a ``ViewResult`` off the wire or the session folder); all
  three place the view's centre with ``view_center``, the one definition;
- **dynamic stage** (views -> one model): ``build_model``, ``dynamic_config`` (the config from a request's
  map), ``model_cloud``, ``DynamicConfig``, ``RegisteredModel``, and the pair work of the incremental model
  during an acquisition: the registration side builds, fingerprints and runs an edge's jobs from the views
  the orchestrator sends (``register_edge`` = ``edge_work`` + ``edge_reply``; ``edge_jobs``,
  ``configuration_names``, the pair job wire forms and records);
- **offline pipeline**: ``reconstruct`` (``objscan reconstruct``);
- **evaluation**: ``evaluate_model``, ``chamfer_metrics``, ``point_errors``, ``sample_mesh``,
  ``view_agreement``, the scan pose errors;
- **clouds**: PLY files, depth frames to points, Open3D conversions;
- **algorithms other packages build on** (importer: turn search and the table; library: GOOD descriptors
  and feature matching; live view: the pre-rotation).

Names are resolved on first use (PEP 562 ``__getattr__``): importing this module costs nothing, so a caller
that only reads a PLY does not load the dynamic stage's dependencies.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from common.api import EdgeReply, EdgeRequest, ViewResult
from common.errors import InvalidRequest
from common.messages import PointCloud, RGBDFrame

if TYPE_CHECKING:  # the types this module's own signatures name
    from services.registration.dynamic.model import DynamicConfig, RegisteredModel
    from services.registration.dynamic.pair import PairJob
    from services.registration.dynamic.views import DynamicView
    from services.registration.static import StaticConfig, StaticViewResult

_HOME = "services.registration"
# public name -> the internal module that defines it (resolved lazily by ``__getattr__``)
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("StaticConfig", "StaticViewResult", "StaticRegistrationError", "NoTableError",
                     "NoObjectError", "register_view"), "static"),
    **dict.fromkeys(("prior_pose_errors", "relative_pose_errors"), "static.pose_errors"),
    "centre_depth": "static.scans",
    "segment_table": "static.table",
    **dict.fromkeys(("DynamicView", "DynamicRegistrationError", "view_center", "view_from_static"), "dynamic.views"),
    **dict.fromkeys(("DynamicConfig", "RegisteredModel", "MapPairs", "build_model", "configuration_names",
                     "early_pair_jobs", "fuse", "process_pool_map"), "dynamic.model"),
    "CombineConfig": "dynamic.combine",
    **dict.fromkeys(("PairConfig", "PairJob", "PairResult", "job_fingerprint", "register_pair"), "dynamic.pair"),
    **dict.fromkeys(("Cloud", "prerotation", "stacking_frame"), "dynamic.preprocess"),
    **dict.fromkeys(("TurnResult", "TurnSearchConfig", "known_turn", "project_to_turn", "search_turn"),
                    "dynamic.turn4dof"),
    **dict.fromkeys(("good_descriptor", "good_distance"), "dynamic.good"),
    "PointCloudInputError": "dynamic.fourpcs_common",
    **dict.fromkeys(("PairJobMessage", "PairResultMessage", "pair_job_from_message", "pair_job_message",
                     "pair_record", "pair_result_from_message", "pair_result_message", "reuse_records"),
                    "pair_wire"),
    **dict.fromkeys(("reconstruct", "default_workers"), "reconstruct"),
    **dict.fromkeys(("chamfer_metrics", "evaluate_model", "point_errors", "sample_mesh", "view_agreement"),
                    "evaluation"),
    **dict.fromkeys(("CloudError", "check_frame", "chromaticity", "downsample", "estimate_normals", "frame_points",
                     "frame_to_cloud", "from_o3d", "o3d_seeded", "read_ply", "to_o3d", "transform_cloud", "write_ply"),
                    "cloud"),
    **dict.fromkeys(("ColorICPConfig", "FeatureMatchConfig", "colored_icp", "fpfh_features", "mean_spacing",
                     "overlap_only", "ransac_feature_match"), "blocks"),
    # the dynamic stage's steps one at a time (the same functions ``build_model`` runs), so a step can be
    # measured alone (``objscan bench`` pair_yaw, turns, global_registration)
    **dict.fromkeys(("global_register", "refine_icp"), "dynamic.global_registration"),
    **dict.fromkeys(("attach_regions", "fit_palette", "neighbour_edges", "preprocess", "quantize"),
                    "dynamic.preprocess"),
    **dict.fromkeys(("fast_local", "global_align", "tilt_deg"), "dynamic.pair"),
    **dict.fromkeys(("chain_to_first", "make_pair_jobs"), "dynamic.model"),
    "loop_closure_error": "dynamic.combine",
    "CONFIGURATIONS": "dynamic.configurations",
    "YawRefineConfig": "dynamic.yaw_refine",
}
# public name -> (module, its name there): steps whose name inside the pair registration is private
_ALIASES: dict[str, tuple[str, str]] = {
    "pair_score_key": ("dynamic.pair", "_score_key"),  # how a pair candidate is ranked (fitness, colour)
    "pair_evaluation_clouds": ("dynamic.pair", "_evaluation_clouds"),  # the scorer a job's candidates share
    "pair_turn_stage": ("dynamic.pair", "_turn_stage"),  # the 4-DoF turn search stage of one job
}


def __getattr__(name: str) -> Any:
    """Resolve an exported name from its internal module on first use (then cached in this module)."""
    where, attr = (_EXPORTS[name], name) if name in _EXPORTS else _ALIASES.get(name, (None, name))
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{_HOME}.{where}"), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS) | set(_ALIASES))


# ------------------------------------------------------------------------------------------------ static stage
def static_config(profile: str = "default", pose_accuracy: dict | None = None) -> StaticConfig:
    """The static stage's config for a named profile, bounded by the arm's stated pose accuracy (a
    ``PoseAccuracy`` map; None or empty: the conservative default). Live scans and replays build it here."""
    from common.pose_accuracy import PoseAccuracy
    from services.registration.static import StaticConfig

    accuracy = PoseAccuracy.from_dict(pose_accuracy) if pose_accuracy else None
    return StaticConfig.for_profile(profile).with_accuracy(accuracy)


def register_scans(frames: Sequence[RGBDFrame], profile: str = "default",
                   pose_accuracy: dict | None = None) -> StaticViewResult:
    """One view's scans registered and the object isolated (``static_config`` of ``profile``)."""
    from services.registration.static import register_view

    return register_view(list(frames), static_config(profile, pose_accuracy))


def view_result(view: int, result: StaticViewResult) -> ViewResult:
    """The wire form of a static result (what the service answers and the session folder stores)."""
    return ViewResult(view=view, cloud=result.object_cloud, table=result.table,
                      center=np.asarray(result.object_center, dtype=np.float64),
                      height=float(result.object_height),
                      scan_poses=np.stack([s.T_base_camera for s in result.scans]).astype(np.float64),
                      figures=result.to_json())


# ------------------------------------------------------------------------------------------------------ views
def view_from_result(v: ViewResult, commanded_turn_deg: float, index: int) -> DynamicView:
    """A dynamic view from the wire form of a static result (the live path, the incremental model, replay):
    the same view ``view_from_static`` makes of the same result, up to the PLY round trip's float32."""
    from services.registration.dynamic.views import DynamicView, view_center

    c = v.cloud
    xyz = np.asarray(c.xyz, np.float32)
    return DynamicView(xyz=xyz,
                       rgb=np.asarray(c.rgb, np.uint8) if c.rgb is not None else np.full(xyz.shape, 128, np.uint8),
                       normals=None if c.normals is None else np.asarray(c.normals, np.float32),
                       table=v.table, center=view_center(v.center, v.table.normal, v.height),
                       commanded_turn_deg=float(commanded_turn_deg), index=index)


def views_from_results(views: Sequence[ViewResult], turns_deg: Sequence[float]) -> list[DynamicView]:
    """Registered views in order, with their commanded cumulative turns, as the dynamic stage's input."""
    return [view_from_result(v, turn, k) for k, (v, turn) in enumerate(zip(views, turns_deg, strict=True))]


# ---------------------------------------------------------------------------------------------- dynamic stage
def dynamic_config(d: dict) -> DynamicConfig:
    """A DynamicConfig from a request's map: ``configuration``, ``paper`` (bool), ``model_voxel``, ``pair``,
    ``accept`` (``AcceptCriteria`` fields), ``preprocess`` (e.g. ``{"palette_views": 2}``, as the incremental
    model sets it), ``outliers`` (e.g. ``{"turn_sigma_deg": 2.0}``). A field the stage does not have is a
    typed error (``InvalidRequest``), not a crash."""
    from services.registration.dynamic.model import DynamicConfig

    if d.get("paper"):
        cfg = DynamicConfig.paper(d.get("configuration", "no_region"))
    else:
        cfg = DynamicConfig(configuration=d.get("configuration", "auto"))
    if "model_voxel" in d:
        cfg = replace(cfg, model_voxel=float(d["model_voxel"]))
    for part in ("pair", "accept", "preprocess", "outliers"):
        if isinstance(d.get(part), dict):
            try:
                cfg = replace(cfg, **{part: replace(getattr(cfg, part), **d[part])})
            except TypeError as exc:
                raise InvalidRequest(f"bad {part} config: {exc}", detail={part: d[part]}) from exc
    return cfg


def with_turn_accuracy(config: dict, turn_accuracy_deg: float | None) -> dict:
    """A dynamic request's config map with the arm's stated turn accuracy (1 sigma, degrees) as the window
    beyond which a view correction is implausible, unless the map sets that window itself: what
    ``session_dynamic_config`` does for a recorded session, so a live scan and ``reconstruct`` of it agree."""
    if not (isinstance(turn_accuracy_deg, (int, float)) and turn_accuracy_deg > 0):
        return dict(config)
    outliers = dict(config.get("outliers") or {})
    outliers.setdefault("turn_sigma_deg", float(turn_accuracy_deg))
    return {**config, "outliers": outliers}


def session_dynamic_config(session_data: dict, config: DynamicConfig | None = None) -> DynamicConfig:
    """The dynamic stage's config for a recorded session (``session.json``): without ``config``, the
    default with the session's stated turn accuracy (as ``with_turn_accuracy`` gives a live scan's request);
    and a fixed camera's views differ by a turn only (``pair.turn_only``), are judged on what neighbours
    share (``accept.judge_overlap``) and its loop's displacement on its own noise
    (``accept.loop_translation_from_noise``), unless ``config`` says otherwise."""
    cfg = config or dynamic_config(with_turn_accuracy({}, session_data.get("turn_accuracy_deg")))
    fixed = session_data.get("camera") == "fixed"
    if cfg.pair.turn_only is None:  # a fixed camera sees one table: every view differs by a turn (pair.py)
        cfg = replace(cfg, pair=replace(cfg.pair, turn_only=fixed))
    if cfg.accept.judge_overlap is None:  # a fixed camera sees the object from the side: pairs judged on overlap
        cfg = replace(cfg, accept=replace(cfg.accept, judge_overlap=fixed))
    if cfg.accept.loop_translation_from_noise is None:  # a fixed camera's loop: judged on its own noise
        cfg = replace(cfg, accept=replace(cfg.accept, loop_translation_from_noise=fixed))
    return cfg


def model_cloud(model: RegisteredModel) -> PointCloud:
    """The model's points as the wire and the session folder carry them."""
    return PointCloud(xyz=np.asarray(model.xyz, np.float32), rgb=np.asarray(model.rgb, np.uint8),
                      normals=np.asarray(model.normals, np.float32))


@dataclass
class EdgeJob:
    """One pair job of the incremental model: edge ``source`` -> ``source - 1`` in one configuration, with the
    fingerprint the dynamic stage matches a stored result by."""

    configuration: str
    job: PairJob
    fingerprint: str


def edge_jobs(views: dict[int, ViewResult], turns_deg: Sequence[float], config: dict, source: int,
              names: Sequence[str] | None = None) -> list[EdgeJob]:
    """The jobs the dynamic stage will run for edge ``source`` (one per configuration of ``names``), built
    exactly as it builds them (same view conversion, same config), so a result computed during the
    acquisition is reused at the end. ``views`` must hold view 0, the palette's views, ``source - 1`` and
    ``source``; empty when the jobs cannot be known yet."""
    from services.registration.dynamic.model import early_pair_jobs
    from services.registration.dynamic.pair import job_fingerprint

    cfg = dynamic_config(config)
    dyn = {i: view_from_result(v, turns_deg[i], i) for i, v in views.items()}
    return [EdgeJob(name, job, job_fingerprint(job))
            for name, job in early_pair_jobs(dyn, source, cfg, None if names is None else list(names))]


def edge_views_needed(config: dict, source: int) -> list[int]:
    """The views ``edge_jobs`` needs for edge ``source``: view 0 (the stacking frame), the palette's views and
    the edge's two."""
    return sorted({0, *range(dynamic_config(config).preprocess.palette_views), source - 1, source})


def dynamic_configurations(config: dict) -> list[str]:
    """The configurations the dynamic stage runs for a request's config map, first one first."""
    from services.registration.dynamic.model import configuration_names

    return configuration_names(dynamic_config(config))


def edge_work(request: EdgeRequest) -> list[EdgeJob]:
    """The jobs an ``EdgeRequest`` asks for that are not done yet: the edge's jobs in the requested
    configurations (``edge_jobs``), less those whose fingerprint the session already stores (``known``).
    CPU: the service runs it in its executor. A view the edge needs and the request lacks is a typed error."""
    views = {int(v.view): v for v in request.views}
    missing = sorted(set(edge_views_needed(request.config, request.source)) - set(views))
    if missing:
        raise InvalidRequest(f"edge {request.source}: the request lacks view(s) {missing}",
                             detail={"missing": missing, "source": request.source})
    known = set(request.known)
    jobs = edge_jobs(views, request.turns_deg, request.config, request.source, request.configurations or None)
    return [e for e in jobs if e.fingerprint not in known]


def edge_reply(jobs: Sequence[EdgeJob], results: Sequence[Any]) -> EdgeReply:
    """The ``EdgeReply`` of ``jobs`` run to ``results`` (``PairResult`` in job order): each result stored
    with its job's fingerprint (``pair_record``), and its configuration."""
    from services.registration.pair_wire import pair_record

    return EdgeReply(records=[pair_record(e.fingerprint, r) for e, r in zip(jobs, results, strict=True)],
                     configurations=[e.configuration for e in jobs])


def register_edge(request: EdgeRequest, map_pairs: Any = None) -> EdgeReply:
    """An ``EdgeRequest`` answered in this process: the jobs not done yet (``edge_work``) run by ``map_pairs``
    (a ``MapPairs``: the service spreads them over its workers; None: one after the other, here)."""
    from services.registration.dynamic.pair import register_pair

    jobs = edge_work(request)
    run = map_pairs if map_pairs is not None else (lambda js: [register_pair(j) for j in js])
    return edge_reply(jobs, run([e.job for e in jobs]) if jobs else [])


__all__ = sorted({*_EXPORTS, *_ALIASES, "EdgeJob", "dynamic_config", "dynamic_configurations", "edge_jobs",
                  "edge_reply", "edge_views_needed", "edge_work", "model_cloud", "register_edge", "register_scans",
                  "session_dynamic_config",
                  "static_config", "view_from_result", "view_result", "views_from_results", "with_turn_accuracy"})
