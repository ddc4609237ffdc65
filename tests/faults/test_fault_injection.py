"""Kill and restart services in the middle of a simulated acquisition; it must still complete, with the
same views and frames as a clean run, no frame lost and none duplicated.

Each acquisition is ``objscan scan``'s flow (the orchestrator's ``run`` key, sim backends, 3 views) on a
cell of separate processes with two registration workers. A fault SIGKILLs a service's process group
while one of its handlers is serving a request (its health says so), waits 2 s and starts it again; the
orchestrator must notice (no reply / liveliness), retry the idempotent call and go on.

Compared with the clean run: the number of registered views and of frames in each; every frame the
orchestrator counted is on disk (not lost) and no frame is on disk twice (pixel hashes).

The main case is one acquisition with every fault in turn (camera while capturing, grasp while
planning, arm while turning the object, a registration worker during a static job and during the model's
pair jobs). All cases are ``slow`` for now (docs/reliability.md). The sim is the world itself: its case
(``test_sim_restart_mid_scan``) needs the twin's state file, which the cell keeps in the test's folder.
"""

from __future__ import annotations

import json

import pytest

from tests.faults.cell import Fault, run_acquisition, start_cell, summarize

pytestmark = pytest.mark.timeout(3000)


def _acquire(root, faults):  # noqa: ANN001, ANN202
    group, specs = start_cell(root)
    try:
        final, injector = run_acquisition(group, root / "session", specs, faults)
    finally:
        group.stop_all()
    return final, injector, summarize(root / "session")


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    final, injector, summary = _acquire(tmp_path_factory.mktemp("clean"), [])
    assert final.get("status") == "done", f"the clean acquisition itself failed: {final.get('last_error')}"
    return summary


def _assert_like_clean(final, injector, summary, clean, root) -> None:  # noqa: ANN001
    assert not injector.errors, injector.errors
    assert final.get("status") == "done", (f"acquisition {final.get('status')}: {final.get('last_error')}; "
                                           f"faults fired: {[f.fired_at for f in injector.fired]}; logs in {root}")
    assert summary.views == clean.views == 3
    assert summary.frames_per_view == clean.frames_per_view
    assert len(summary.all_frame_hashes) == summary.captures, "a counted capture is missing on disk"
    assert len(set(summary.all_frame_hashes)) == len(summary.all_frame_hashes), "a frame was saved twice"


@pytest.mark.slow
def test_every_service_killed_in_turn_acquisition_completes_like_a_clean_run(clean, tmp_path):
    faults = [Fault("camera", "scan", view=0), Fault("grasp", "plan_grasp", view=0), Fault("arm", "turn", view=0),
              Fault("sim", "scan", view=1), Fault("registration*", "register", view=1),
              Fault("registration*", "model")]
    final, injector, summary = _acquire(tmp_path, faults)
    print(json.dumps({"fired": [f.fired_at for f in injector.fired], "captures": summary.captures,
                      "clean_captures": clean.captures}, default=str))
    assert [f.fired_at["label"].split("-")[0] for f in injector.fired] == [
        "camera", "grasp", "arm", "sim", "registration", "registration"]
    _assert_like_clean(final, injector, summary, clean, tmp_path)
    report = json.loads((tmp_path / "session" / "report.json").read_text())
    assert report, "the model's report exists"


@pytest.mark.slow
@pytest.mark.extended  # each is a whole acquisition; the all-services case above covers them in CI
@pytest.mark.parametrize("fault", [
    Fault("camera", "scan", view=1),
    Fault("arm", "scan", view=1),
    Fault("arm", "turn", view=1),
    Fault("grasp", "plan_grasp", view=1),
    Fault("registration*", "register", view=0),
    Fault("registration*", "model"),
], ids=lambda f: f"{f.label}-{f.state}-{f.view}")
def test_one_service_killed(clean, tmp_path, fault):
    final, injector, summary = _acquire(tmp_path, [fault])
    _assert_like_clean(final, injector, summary, clean, tmp_path)


def _sim_restart(clean, tmp_path, fault: Fault) -> None:  # noqa: ANN001
    final, injector, summary = _acquire(tmp_path, [fault])
    logs = tmp_path / "logs"
    arm_log = (logs / "arm.log").read_text(errors="replace")
    print(json.dumps({"fired": [f.fired_at for f in injector.fired], "captures": summary.captures,
                      "clean_captures": clean.captures, "elapsed_s": final.get("elapsed_s"),
                      "orchestrator_retries": (logs / "orchestrator.log").read_text(errors="replace").count("retrying"),
                      "arm_twin_retries": arm_log.count("sending again"),
                      "arm_resyncs": arm_log.count("joints re-sent"),
                      # not asserted: a frame the twin rendered (and counted in its state file) whose reply was
                      # lost is rendered again with the next sequence number, so later frames' noise differs
                      # from the clean run's (still nothing lost or duplicated)
                      "frames_identical_to_clean": summary.all_frame_hashes == clean.all_frame_hashes},
                     default=str))
    assert [f.fired_at["label"] for f in injector.fired] == ["sim"]
    sim_log = (logs / "sim.log").read_text(errors="replace")
    assert "world restored from the state file" in sim_log, "the restarted twin did not load the saved world"
    _assert_like_clean(final, injector, summary, clean, tmp_path)


@pytest.mark.slow
@pytest.mark.extended
def test_sim_restart_mid_scan(clean, tmp_path):
    """The twin is the world: killed while serving during the scan (rendering, or taking set-points), it
    comes back from its state file (services/sim/state_file.py) with the object where it was, the arm's
    joints re-sent by the twin link, and the acquisition completes like the clean run."""
    _sim_restart(clean, tmp_path, Fault("sim", "scan", view=0))


@pytest.mark.slow
@pytest.mark.extended
def test_sim_restart_during_the_turn(clean, tmp_path):
    """Killed while serving the grasp-and-turn (the gripper closing on the object, set-points of the approach,
    the carry with the object held, the set-down): the arm's twin link sends the interrupted command again
    to the restarted twin, which holds the object or not as its saved world says, and the turn goes on."""
    _sim_restart(clean, tmp_path, Fault("sim", "turn", view=0))
