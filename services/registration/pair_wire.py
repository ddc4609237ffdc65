"""Pair jobs and their results on the wire, so registration workers on any machine can share the work.

``PairJob``/``PairResult`` are the dynamic stage's plain dataclasses; these messages carry exactly their
fields (clouds as ``PointCloud``, the frozen ``PairConfig`` as a map rebuilt on arrival).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from common.codec import Message, array_field
from common.errors import InvalidRequest
from common.messages import PointCloud
from services.registration.dynamic.pair import PairConfig, PairJob, PairResult
from services.registration.dynamic.preprocess import Cloud
from services.registration.dynamic.revolution import RevolutionConfig
from services.registration.dynamic.turn4dof import TurnSearchConfig
from services.registration.dynamic.views import DynamicRegistrationError
from services.registration.dynamic.yaw_refine import YawRefineConfig


@dataclass(kw_only=True)
class PairJobMessage(Message):
    index: int
    source_view: int
    target_view: int
    source: PointCloud
    target: PointCloud
    center: np.ndarray = array_field("<f8", (3,))
    axis: np.ndarray = array_field("<f8", (3,))
    prior: np.ndarray = array_field("<f8", (4, 4))
    config: dict = field(default_factory=dict)
    source_regions: list[PointCloud] = field(default_factory=list)
    target_regions: list[PointCloud] = field(default_factory=list)
    region_pairs: list[list[int]] = field(default_factory=list)
    # speculative work (the incremental model's other configurations): run at the lowest CPU priority, so it
    # only takes cores nothing else wants (pair_pool.py)
    background: bool = False


@dataclass(kw_only=True)
class PairResultMessage(Message):
    index: int
    source_view: int
    target_view: int
    T: np.ndarray = array_field("<f8", (4, 4))
    fitness: float = 0.0
    rmse: float = 0.0
    color_fitness: float = 0.0
    path: str = ""
    candidate: str = ""
    seconds: float = 0.0
    attempts: int = 0
    color_icp_failures: int = 0
    detail: dict = field(default_factory=dict)
    yaw_from_prior: bool = False


def _cloud_msg(c: Cloud) -> PointCloud:
    return PointCloud(xyz=np.asarray(c.xyz, np.float32), rgb=np.asarray(c.rgb, np.uint8),
                      normals=np.asarray(c.normals, np.float32))


def _cloud(p: PointCloud) -> Cloud:
    n = len(p)
    rgb = p.rgb if p.rgb is not None else np.zeros((n, 3), np.uint8)
    nrm = p.normals if p.normals is not None else np.zeros((n, 3), np.float32)
    return Cloud(np.array(p.xyz, np.float32), np.array(rgb, np.uint8), np.array(nrm, np.float32))


def _lists(d: dict) -> dict:
    """A config map with tuples as lists, nested maps too (what msgpack carries)."""
    return {k: _lists(v) if isinstance(v, dict) else list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def _config_dict(cfg: PairConfig) -> dict:
    return _lists(dataclasses.asdict(cfg))


def _rebuild(cls: type, d: dict, what: str):  # noqa: ANN202
    """A frozen config dataclass from its wire map: lists back to tuples, nested configs rebuilt."""
    if not isinstance(d, dict):
        raise InvalidRequest(f"{what} must be a map")
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = set(d) - set(known)
    if unknown:
        raise InvalidRequest(f"unknown {what} keys {sorted(unknown)}")
    out = {}
    for k, v in d.items():
        if k in _NESTED.get(cls, {}):
            v = _rebuild(_NESTED[cls][k], v, f"{what}.{k}")
        elif isinstance(v, list):
            v = tuple(v)
        out[k] = v
    try:
        return cls(**out)
    except (TypeError, ValueError, DynamicRegistrationError) as exc:
        raise InvalidRequest(f"bad {what}: {exc}") from None


_NESTED: dict[type, dict[str, type]] = {PairConfig: {"turn_search": TurnSearchConfig, "yaw_refine": YawRefineConfig,
                                                     "revolution": RevolutionConfig}}


def _config(d: dict) -> PairConfig:
    return _rebuild(PairConfig, d, "pair config")


def pair_job_message(job: PairJob, background: bool = False) -> PairJobMessage:
    return PairJobMessage(background=background, index=job.index, source_view=job.source_view,
                          target_view=job.target_view,
                          source=_cloud_msg(job.source), target=_cloud_msg(job.target),
                          center=np.asarray(job.center, np.float64), axis=np.asarray(job.axis, np.float64),
                          prior=np.asarray(job.prior, np.float64), config=_config_dict(job.config),
                          source_regions=[_cloud_msg(c) for c in job.source_regions],
                          target_regions=[_cloud_msg(c) for c in job.target_regions],
                          region_pairs=[list(map(int, p)) for p in job.region_pairs])


def pair_job_from_message(msg: Message | None) -> PairJob:
    if not isinstance(msg, PairJobMessage):
        raise InvalidRequest("expected a PairJobMessage", detail={"got": type(msg).__name__})
    return PairJob(index=msg.index, source_view=msg.source_view, target_view=msg.target_view,
                   source=_cloud(msg.source), target=_cloud(msg.target), center=np.array(msg.center),
                   axis=np.array(msg.axis), config=_config(msg.config),
                   source_regions=[_cloud(c) for c in msg.source_regions],
                   target_regions=[_cloud(c) for c in msg.target_regions],
                   region_pairs=[(int(a), int(b)) for a, b in msg.region_pairs], prior=np.array(msg.prior))


def _plain(obj):  # noqa: ANN001, ANN202 - detail maps: numpy to Python
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def pair_result_message(r: PairResult) -> PairResultMessage:
    return PairResultMessage(index=r.index, source_view=r.source_view, target_view=r.target_view,
                             T=np.asarray(r.T, np.float64), fitness=float(r.fitness), rmse=float(r.rmse),
                             color_fitness=float(r.color_fitness), path=r.path, candidate=r.candidate,
                             seconds=float(r.seconds), attempts=int(r.attempts),
                             color_icp_failures=int(r.color_icp_failures), detail=_plain(r.detail),
                             yaw_from_prior=bool(r.yaw_from_prior))


def pair_result_from_message(m: PairResultMessage) -> PairResult:
    return PairResult(index=m.index, source_view=m.source_view, target_view=m.target_view, T=np.array(m.T),
                      fitness=m.fitness, rmse=m.rmse, color_fitness=m.color_fitness, path=m.path,
                      candidate=m.candidate, seconds=m.seconds, attempts=m.attempts,
                      color_icp_failures=m.color_icp_failures, detail=m.detail, yaw_from_prior=m.yaw_from_prior)


def pair_record(fingerprint: str, r: PairResult) -> dict:
    """JSON form of a finished pair job with the fingerprint of the job it answers (session folder, reuse)."""
    return {"fingerprint": fingerprint, "index": r.index, "source_view": r.source_view,
            "target_view": r.target_view, "T": np.asarray(r.T, float).tolist(), "fitness": float(r.fitness),
            "rmse": float(r.rmse), "color_fitness": float(r.color_fitness), "path": r.path,
            "candidate": r.candidate, "seconds": float(r.seconds), "attempts": int(r.attempts),
            "color_icp_failures": int(r.color_icp_failures), "detail": _plain(r.detail),
            "yaw_from_prior": bool(r.yaw_from_prior)}


def reuse_records(records: object) -> dict[str, PairResult]:
    """fingerprint -> PairResult from ``pair_record`` maps (a ``DynamicRequest``'s ``reuse_pairs``).

    Anything malformed is a typed error: a reused result goes into the model unchecked, so it must be whole.
    """
    if not isinstance(records, list):
        raise InvalidRequest("reuse_pairs must be a list of pair records")
    out: dict[str, PairResult] = {}
    for i, d in enumerate(records):
        try:
            T = np.asarray(d["T"], dtype=np.float64)
            if T.shape != (4, 4) or not np.isfinite(T).all() or not isinstance(d["fingerprint"], str):
                raise ValueError("T must be a finite 4x4 and fingerprint a string")
            r = PairResult(index=int(d["index"]), source_view=int(d["source_view"]),
                           target_view=int(d["target_view"]), T=T, fitness=float(d["fitness"]),
                           rmse=float(d["rmse"]), color_fitness=float(d["color_fitness"]), path=str(d["path"]),
                           candidate=str(d["candidate"]), seconds=float(d["seconds"]),
                           attempts=int(d.get("attempts", 0)), color_icp_failures=int(d.get("color_icp_failures", 0)),
                           detail=dict(d.get("detail", {})), yaw_from_prior=bool(d.get("yaw_from_prior", False)))
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidRequest(f"reuse_pairs[{i}] is not a pair record: {exc}") from exc
        out[d["fingerprint"]] = r
    return out
