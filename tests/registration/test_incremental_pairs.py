"""The incremental model's contract at the algorithm level: a pair job built while later views are still to
come is the very job ``build_model`` runs at the end, so its result can be reused, and the model is the same
as computing every pair at the end (docs/dynamic-registration.md, "Incremental model")."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from services.registration.dynamic.configurations import CONFIGURATIONS
from services.registration.dynamic.model import DynamicConfig, build_model, early_pair_job, early_pair_jobs
from services.registration.dynamic.pair import PairResult, job_fingerprint, register_pair
from services.registration.dynamic.preprocess import PreprocessConfig
from services.registration.dynamic.views import DynamicRegistrationError
from tests.conftest import shared_data

CONFIG = DynamicConfig(configuration="no_region", preprocess=PreprocessConfig(palette_views=2))


@pytest.fixture(scope="module")
def views():
    shared_data("hope", "milk")
    from bench.synthetic import synthetic_views

    return synthetic_views("milk", profile="hand-turned", seed=3, voxel=0.002).views


@pytest.fixture(scope="module")
def views_1mm():
    shared_data("hope", "milk")
    from bench.synthetic import synthetic_views

    return synthetic_views("milk", profile="hand-turned", seed=3).views


def _quick_result(job):
    """A stand-in pair result (identity, as pre-rotated): fast tests check which jobs run, not their quality."""
    return PairResult(job.index, job.source_view, job.target_view, np.eye(4), 0.9, 0.001, 0.5, "prior", "full", 0.0)


class Recorder:
    """A ``map_pairs`` that records the fingerprint of every job it is given."""

    def __init__(self):
        self.seen: list[str] = []

    def __call__(self, jobs):
        self.seen += [job_fingerprint(j) for j in jobs]
        return [_quick_result(j) for j in jobs]


def _as_captured(views, config=CONFIG, run=register_pair):
    """Pair results as the acquisition makes them: edge k-1 as soon as view k exists, never seeing later views."""
    reuse = {}
    for k in range(1, len(views)):
        seen = {i: v for i, v in enumerate(views[:k + 1])}
        job = early_pair_job(seen, k, config)
        assert job is not None and (job.source_view, job.target_view, job.index) == (k, k - 1, k - 1)
        reuse[job_fingerprint(job)] = run(job)
    return reuse


def test_jobs_built_during_the_acquisition_are_the_jobs_of_the_end(views):
    early = _as_captured(views, run=_quick_result)
    at_end = Recorder()
    build_model(views, CONFIG, map_pairs=at_end)
    assert len(at_end.seen) == 12 and set(at_end.seen[:11]) == set(early)  # the 11 neighbours: identical jobs
    with_reuse = Recorder()
    model = build_model(views, CONFIG, map_pairs=with_reuse, reuse=early)
    assert with_reuse.seen == at_end.seen[11:]  # only the loop closure is run at the end
    assert model.timings["pairs"] == {"reused": 11, "computed": 1}


@pytest.mark.slow  # 2 x 12 real pair registrations: ~25 s idle, over a minute on the shared box
def test_incremental_pairs_give_the_same_model_as_computing_them_at_the_end(views_1mm):
    views = views_1mm
    reuse = _as_captured(views)
    incremental = build_model(views, CONFIG, reuse=reuse)
    at_end = build_model(views, CONFIG)
    # bit for bit only where the pair path is deterministic: the prior path is; the global fallback's 4PCS
    # stops at a time budget (max_time_s), so two end-of-run computations of such a pair differ as well
    assert all(e.path == "prior" for e in at_end.edges), [e.path for e in at_end.edges]
    # 11 neighbour pairs reused; only the loop closure (its prior chains all of them) is computed at the end
    assert incremental.timings["pairs"] == {"reused": 11, "computed": 1}
    assert at_end.timings["pairs"] == {"reused": 0, "computed": 12}
    for a, b in zip(incremental.edges, at_end.edges, strict=True):
        assert np.allclose(a.T, b.T, atol=1e-9) and abs(a.fitness - b.fitness) < 1e-9
    for a, b in zip(incremental.T_model_view, at_end.T_model_view, strict=True):
        assert np.allclose(a, b, atol=1e-9)
    assert len(incremental) == len(at_end) and np.allclose(incremental.xyz, at_end.xyz, atol=1e-7)


AUTO = replace(CONFIG, configuration="auto")


def _all_configurations_as_captured(views, config=AUTO):
    """Every configuration's neighbour jobs as the acquisition builds them: fingerprint -> (configuration, job)."""
    early = {}
    for k in range(1, len(views)):
        built = early_pair_jobs(dict(enumerate(views[:k + 1])), k, config)
        assert [name for name, _ in built] == list(CONFIGURATIONS)  # the first configuration's job first
        for name, job in built:
            assert (job.source_view, job.target_view) == (k, k - 1)
            assert job.config.regions == CONFIGURATIONS[name][0] and job.config.crop == CONFIGURATIONS[name][1]
            early[job_fingerprint(job)] = (name, job)
    return early


class RejectFirst(Recorder):
    """Stand-in results, except the first configuration's loop closure: 20 degrees off, so it is rejected."""

    def __call__(self, jobs):
        out = super().__call__(jobs)
        for j, r in zip(jobs, out, strict=True):
            if j.source_view == 0 and not j.config.regions and not j.config.crop:
                r.T = np.array([[np.cos(0.35), -np.sin(0.35), 0, 0], [np.sin(0.35), np.cos(0.35), 0, 0],
                                [0, 0, 1, 0], [0, 0, 0, 1.0]])
        return out


def test_every_configurations_early_jobs_are_its_jobs_at_the_end(views):
    """Region configurations included: each view is segmented on its own and each edge's regions paired by
    GOOD from its two views only, so the job built at view k has the fingerprint ``build_model`` builds at the
    end, configuration by configuration."""
    early = _all_configurations_as_captured(views)
    assert len(early) == 4 * 11  # four different jobs per edge
    region_jobs = [job for name, job in early.values() if CONFIGURATIONS[name][0]]
    assert all(job.region_pairs and job.source_regions and job.target_regions for job in region_jobs)
    at_end = RejectFirst()
    model = build_model(views, AUTO, map_pairs=at_end)  # staged: the first is rejected, so all four run
    assert set(model.candidates) == set(CONFIGURATIONS)
    assert len(at_end.seen) == 48
    ends = [fp for fp in at_end.seen if fp not in early]
    assert len(ends) == 4  # per configuration only the loop closure was not known early
    for name in CONFIGURATIONS:  # ... and every neighbour job of every configuration was
        assert sum(1 for fp in at_end.seen if fp in early and early[fp][0] == name) == 11
    reused = RejectFirst()
    again = build_model(views, AUTO, map_pairs=reused, reuse={fp: _quick_result(job) for fp, (_, job) in early.items()})
    assert again.timings["pairs"] == {"reused": 44, "computed": 4} and sorted(reused.seen) == sorted(ends)
    assert again.configuration == model.configuration != "no_region"


def test_the_early_jobs_of_one_configuration_alone_and_of_all_agree(views):
    seen = dict(enumerate(views[:4]))
    every = dict(early_pair_jobs(seen, 3, AUTO))
    for name in CONFIGURATIONS:
        alone = early_pair_job(seen, 3, replace(CONFIG, configuration=name))
        assert job_fingerprint(alone) == job_fingerprint(every[name])
    assert early_pair_jobs(seen, 3, DynamicConfig()) == []  # palette from all views: not known before the end


def test_a_changed_view_or_config_is_recomputed_not_reused(views):
    reuse = _as_captured(views, run=_quick_result)
    moved = list(views)
    v5 = moved[5]
    moved[5] = replace(v5, xyz=np.asarray(v5.xyz) + np.float32(0.0005))  # view 5 re-scanned: 0.5 mm elsewhere
    model = build_model(moved, CONFIG, map_pairs=Recorder(), reuse=reuse)
    assert model.timings["pairs"] == {"reused": 9, "computed": 3}  # edges 4 (5->4) and 5 (6->5), and the loop
    other = replace(CONFIG, pair=replace(CONFIG.pair, fitness_distance=0.004))
    assert build_model(views, other, map_pairs=Recorder(), reuse=reuse).timings["pairs"]["reused"] == 0


def test_no_early_job_when_it_could_still_change(views):
    seen = dict(enumerate(views[:4]))
    assert early_pair_job(seen, 3, DynamicConfig()) is None  # palette from all views: view 11 would change it
    assert early_pair_job({0: views[0], 2: views[2], 3: views[3]}, 3, CONFIG) is None  # palette view 1 missing
    with pytest.raises(DynamicRegistrationError):
        PreprocessConfig(palette_views=-1)


def test_reused_results_travel_exactly_and_malformed_ones_are_refused():
    from common.errors import InvalidRequest
    from services.registration.api import dynamic_config
    from services.registration.pair_wire import pair_record, reuse_records

    rng = np.random.default_rng(0)
    T = np.eye(4)
    T[:3, 3] = rng.normal(size=3)
    r = PairResult(4, 5, 4, T, 0.8123456789, 0.0012345, 0.51, "prior", "full", 1.5, detail={"k": np.float32(2)})
    (back,) = reuse_records(json.loads(json.dumps([pair_record("abc", r)]))).values()
    assert np.array_equal(back.T, r.T) and back.fitness == r.fitness and back.rmse == r.rmse
    for bad in ("x", [{"fingerprint": "a"}], [pair_record("a", r) | {"T": [[1, 2], [3, 4]]}],
                [pair_record("a", r) | {"T": np.full((4, 4), np.nan).tolist()}]):
        with pytest.raises(InvalidRequest):
            reuse_records(bad)
    assert dynamic_config({"preprocess": {"palette_views": 2}}).preprocess.palette_views == 2
    with pytest.raises(InvalidRequest):
        dynamic_config({"preprocess": {"no_such_knob": 1}})


class PerConfiguration(Recorder):
    """Stand-in results that differ per configuration (a small yaw of 1 + 2*regions + crop degrees), so each
    configuration's loop closure starts from its own chain."""

    def __call__(self, jobs):
        out = super().__call__(jobs)
        for j, r in zip(jobs, out, strict=True):
            a = np.radians(1.0 + 2.0 * j.config.regions + j.config.crop)
            r.T = np.array([[np.cos(a), -np.sin(a), 0, 0], [np.sin(a), np.cos(a), 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        return out


def test_configurations_run_together_are_the_configurations_run_one_by_one(views):
    """``run_configurations`` shares its pair rounds between configurations (results matched by position):
    the jobs, each loop closure's prior and the outcomes are those of running each configuration alone."""
    from services.registration.dynamic.model import run_configuration, run_configurations
    from services.registration.dynamic.preprocess import preprocess

    names = ["no_region_crop", "region", "region_crop"]
    prep = preprocess(views, AUTO.preprocess)
    together = PerConfiguration()
    joint = run_configurations(prep, names, AUTO, together)
    alone = PerConfiguration()
    single = [run_configuration(prep, name, AUTO, alone) for name in names]
    assert len(together.seen) == len(alone.seen) == 36 and sorted(together.seen) == sorted(alone.seen)
    for a, b in zip(joint, single, strict=True):
        assert a.name == b.name and a.score == b.score and a.loop == b.loop
        assert [r.source_view for r in a.results] == [r.source_view for r in b.results]
        assert all(np.array_equal(x.T, y.T) for x, y in zip(a.results, b.results, strict=True))
    assert len({round(o.loop["rotation_deg"], 6) for o in joint}) == 3  # three different chains, kept apart
