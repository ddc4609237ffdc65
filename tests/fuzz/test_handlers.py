"""Every queryable of the real services, sent malformed and hostile payloads: each answers with a typed
``Error`` (or a proper reply to a request that happened to be valid) and every service stays alive.

The whole cell runs as separate processes on loopback (sim backends). For every key we send random bytes,
truncated valid requests, messages of the wrong type, the expected type with hostile fields (wrong types,
NaN/inf, huge integers, lying arrays), absurd sizes, and no payload at all. Afterwards every service must
still hold the same liveliness token, answer its health query and its process must be running.

``orchestrator/run`` receives only undecodable payloads: any decodable message there starts a real
acquisition (by design: its parameters are optional).
"""

from __future__ import annotations

import os
import random
import time
from collections import Counter

import numpy as np
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from common import keys
from common.api import CaptureRequest, GripperRequest, MoveRequest, SceneRequest
from common.client import live_services, request_sync
from common.codec import Message, decode
from common.errors import WireError
from common.messages import Error, Health, Ok, Request
from services.cell import cell_specs
from tests.fuzz.strategies import MESSAGE_TYPES, any_valid_message, hostile_wire, pack, valid_message

pytestmark = pytest.mark.filterwarnings("ignore::hypothesis.errors.NonInteractiveExampleWarning")

ROBOT = keys.DEFAULT_ROBOT
PER_KEY = int(os.environ.get("OBJSCAN_HANDLER_FUZZ_EXAMPLES", "12"))
REPLY_TIMEOUT_S = 60.0

# key -> the request type its handler expects (None: takes no request)
EXPECTED: dict[str, str | None] = {
    keys.camera_capture(ROBOT): "CaptureRequest",
    keys.arm(ROBOT, "move"): "MoveRequest",
    keys.arm(ROBOT, "gripper"): "GripperRequest",
    keys.arm(ROBOT, "stop"): "Request",
    keys.arm(ROBOT, "scene"): "SceneRequest",
    keys.arm(ROBOT, "state"): None,
    keys.sim(ROBOT, "render"): "CaptureRequest",
    keys.sim(ROBOT, "joints"): "JointState",
    keys.sim(ROBOT, "gripper"): "GripperRequest",
    keys.sim(ROBOT, "world"): "Request",
    keys.REGISTRATION_STATIC: "StaticRequest",
    keys.REGISTRATION_DYNAMIC: "DynamicRequest",
    keys.GRASP_PLAN: "GraspRequest",
    keys.orchestrator(ROBOT, "status"): None,
    keys.orchestrator(ROBOT, "stop"): None,
}
UNDECODABLE_ONLY = {keys.orchestrator(ROBOT, "run")}

# Requests that decode but ask for absurd amounts of work or memory: each must be refused or fail fast.
ABSURD: list[tuple[str, Message]] = [
    (keys.sim(ROBOT, "world"), Request(params={"op": "gt_points", "n": 10**13})),
    (keys.sim(ROBOT, "world"), Request(params={"op": "gt_points", "n": -5})),
    (keys.sim(ROBOT, "world"), Request(params={"op": "gt_points", "n": "many"})),
    (keys.sim(ROBOT, "world"), Request(params={"op": "turn", "angle_deg": "x"})),
    (keys.sim(ROBOT, "world"), Request(params={"op": "no-such-op"})),
    (keys.sim(ROBOT, "world"), Request(params={"op": ["state"]})),
    (keys.sim(ROBOT, "render"), CaptureRequest(width=10**7, height=10**7)),
    (keys.sim(ROBOT, "render"), CaptureRequest(width=-3, height=2)),
    (keys.arm(ROBOT, "move"), MoveRequest(kind="joints", q=np.full(6, 1e6))),
    (keys.arm(ROBOT, "move"), MoveRequest(kind="joints", q=np.zeros(2))),
    (keys.arm(ROBOT, "move"), MoveRequest(kind="pose", target=np.zeros((4, 4)))),
    (keys.arm(ROBOT, "gripper"), GripperRequest(opening=-1.0, force=1e9)),
    (keys.arm(ROBOT, "scene"), SceneRequest(center=np.zeros(3), extent=np.full(3, 1e300))),
    (keys.registration_worker_pair("{instance}"), Request(params={})),
]


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    from common.launcher import ServiceGroup

    root = tmp_path_factory.mktemp("cell")
    group = ServiceGroup(log_dir=root / "logs")
    try:
        specs = cell_specs()
        for spec in specs:
            if spec.service == "orchestrator":
                spec.args += ["--sessions", str(root / "sessions")]
        group.launch(specs, timeout=240)
        yield group
    finally:
        group.stop_all()


def _ask(session: zenoh.Session, key: str, payload: bytes | None) -> list[Message]:
    """Send raw bytes (or nothing) and decode every reply; a reply that does not decode fails the test."""
    kwargs = {"payload": payload} if payload is not None else {}
    replies = list(session.get(key, timeout=REPLY_TIMEOUT_S, **kwargs))
    out = []
    for r in replies:
        sample = r.ok if r.ok is not None else r.err
        out.append(decode(sample.payload.to_bytes()))
    return out


def _payloads(expected: str | None, rng: random.Random, undecodable_only: bool) -> list[tuple[str, bytes | None]]:
    """(kind, payload) pairs for one key."""
    out: list[tuple[str, bytes | None]] = []
    for _ in range(max(2, PER_KEY // 4)):
        out.append(("random", rng.randbytes(rng.randint(1, 300))))
    base_type = MESSAGE_TYPES[expected] if expected else MESSAGE_TYPES["Request"]
    for _ in range(max(2, PER_KEY // 4)):
        valid = valid_message(base_type).example().encode()
        out.append(("truncated", valid[: rng.randint(1, len(valid) - 1)]))
    out.append(("trailing", Ok().encode() + b"\x00"))
    out.append(("deep", b"\x91" * 5000 + b"\x00"))
    out.append(("huge_bin", b"\xc6\xff\xff\xff\xff" + b"\x00" * 8))
    if undecodable_only:
        return out
    out.append(("empty", None))
    for _ in range(max(2, PER_KEY // 4)):
        out.append(("wrong_type", any_valid_message.example().encode()))
    if expected:
        for _ in range(max(3, PER_KEY // 2)):
            out.append(("hostile", pack(hostile_wire(MESSAGE_TYPES[expected]).example())))
    return out


def _snapshot(group) -> dict[str, str]:  # noqa: ANN001 - ServiceGroup
    return {s: i for s, i in live_services(group.session, timeout=1.0)}


def test_every_handler_answers_malformed_payloads_with_typed_errors_and_survives(cell):
    session = cell.session
    before = _snapshot(cell)
    assert set(before) >= {"sim", "camera", "arm", "registration", "grasp", "orchestrator"}
    rng = random.Random(10)
    targets = dict(EXPECTED)
    targets[keys.registration_worker_pair(before["registration"])] = "PairJobMessage"
    for key in UNDECODABLE_ONLY:
        targets[key] = None
    codes: Counter[str] = Counter()
    internal: list[str] = []
    t0 = time.monotonic()
    for key, expected in targets.items():
        for kind, payload in _payloads(expected, rng, key in UNDECODABLE_ONLY):
            replies = _ask(session, key, payload)
            assert len(replies) == 1, f"{key} {kind}: {len(replies)} replies"
            reply = replies[0]
            undecodable = payload is not None and kind in ("random", "truncated", "trailing", "deep", "huge_bin")
            if undecodable:
                try:
                    decode(payload)
                    undecodable = False  # random bytes that happen to decode (rare): any reply is fine
                except WireError:
                    pass
            if undecodable:
                assert isinstance(reply, Error), f"{key} {kind}: undecodable payload got {type(reply).__name__}"
            if isinstance(reply, Error):
                codes[reply.code] += 1
                if reply.code == "internal":
                    internal.append(f"{key} {kind}: {reply.message[:160]}")
    for key, msg in ABSURD:
        key = key.replace("{instance}", before["registration"])
        t1 = time.monotonic()
        reply = _ask(session, key, msg.encode())
        assert len(reply) == 1 and time.monotonic() - t1 < REPLY_TIMEOUT_S
        if isinstance(reply[0], Error):
            codes[reply[0].code] += 1
            if reply[0].code == "internal":
                internal.append(f"{key} absurd {msg}: {reply[0].message[:160]}")
    print(f"\n{sum(codes.values())} error replies in {time.monotonic() - t0:.1f} s by code: {dict(codes)}")
    for line in internal:  # untyped handler failures: reported to the service owners (docs/reliability.md)
        print("internal:", line)
    # every service is still the same live process and answers
    after = _snapshot(cell)
    assert after == before, f"a service restarted or vanished: {before} -> {after}"
    for label, proc in cell.procs.items():
        assert proc.poll() is None, f"{label} exited with {proc.returncode}"
    for service, instance in after.items():
        h = request_sync(session, keys.health(service, instance), timeout=10)
        assert isinstance(h, Health) and h.status == "ok"
    # and the arm still works for a sound request (a hostile stop may have latched the e-stop: reset it)
    request_sync(session, keys.arm(ROBOT, "stop"), Request(params={"reset": True}), timeout=10)
    assert isinstance(request_sync(session, keys.arm(ROBOT, "state"), timeout=10), Message)


@settings(max_examples=int(os.environ.get("OBJSCAN_FUZZ_EXAMPLES", "150")) // 3, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(st.sampled_from(sorted(EXPECTED)),
       st.binary(min_size=1, max_size=200) | any_valid_message.map(lambda m: m.encode()))
def test_hypothesis_drives_any_payload_to_any_key(cell, key, payload):
    """Hypothesis picks keys and payloads (it shrinks a failure to the smallest one); one reply each."""
    replies = _ask(cell.session, key, payload)
    assert len(replies) == 1
    try:
        decode(payload)
    except WireError:
        assert isinstance(replies[0], Error)
