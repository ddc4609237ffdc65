"""The service runtime across real OS processes talking Zenoh over loopback (multicast off, free ports)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from common import keys
from common.client import live_services, request_sync
from common.errors import RemoteError, ServiceUnavailable
from common.launcher import ProcessSpec
from common.messages import Health, Ok, PointCloud, Request, RGBDFrame


@pytest.fixture
def echo(service_group):
    service_group.launch([ProcessSpec("tests.support.echo_service", ["--instance", "e1"], service="echo")])
    return service_group


def test_frame_and_large_cloud_cross_processes(echo):
    s = echo.session
    frame = request_sync(s, "objscan/test/e1/frame", timeout=20)
    assert isinstance(frame, RGBDFrame)
    assert frame.color.shape == (480, 848, 3) and frame.depth.shape == (480, 848)
    expected = np.random.default_rng(0).integers(0, 255, (480, 848, 3), dtype=np.uint8)
    assert np.array_equal(frame.color, expected)
    cloud = request_sync(s, "objscan/test/e1/cloud", timeout=30)
    assert isinstance(cloud, PointCloud) and len(cloud) == 300_000
    assert cloud.rgb.shape == (300_000, 3) and cloud.normals.dtype == np.float32


def test_request_roundtrip_and_error_reply(echo):
    s = echo.session
    sent = Request(params={"a": 1, "arr": np.arange(5.0)})
    back = request_sync(s, "objscan/test/e1/echo", sent, timeout=10)
    assert isinstance(back, Request) and back.params["a"] == 1
    assert np.array_equal(back.params["arr"], np.arange(5.0))
    with pytest.raises(RemoteError) as err:
        request_sync(s, "objscan/test/e1/crash", timeout=10)
    assert err.value.code == "internal" and "deliberate" in err.value.message
    # the service survived the crash and still answers
    assert isinstance(request_sync(s, "objscan/test/e1/echo", Ok(), timeout=10), Ok)


def test_malformed_payload_gets_typed_error(echo):
    import zenoh

    s = echo.session
    for payload in (b"\xc1\xff", b"\x93\x01\x02", b""):
        replies = list(s.get("objscan/test/e1/echo", payload=payload, timeout=10))
        assert len(replies) == 1 and replies[0].ok is not None
        from common.codec import decode

        msg = decode(replies[0].ok.payload.to_bytes())
        assert msg.code in ("malformed", "empty") or msg.code.startswith("bad"), msg
    assert isinstance(request_sync(s, "objscan/test/e1/echo", Ok(), timeout=10), Ok)
    del zenoh


def test_health_answers_while_cpu_burns(echo):
    s = echo.session
    result: dict[str, object] = {}

    def burn() -> None:
        result["reply"] = request_sync(s, "objscan/test/e1/burn", Request(params={"seconds": 2.0}), timeout=20)

    t = threading.Thread(target=burn)
    t.start()
    time.sleep(0.4)  # the burn is under way
    latencies = []
    for _ in range(5):
        t0 = time.perf_counter()
        h = request_sync(s, keys.health("echo", "e1"), timeout=5)
        latencies.append(time.perf_counter() - t0)
        assert isinstance(h, Health) and h.busy >= 1
        time.sleep(0.1)
    t.join()
    assert isinstance(result["reply"], Ok)
    assert max(latencies) < 0.1, latencies


def _wait_for(predicate, timeout: float = 15.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.2)
    return predicate()


def test_killed_service_vanishes_from_liveliness(echo):
    assert _wait_for(lambda: ("echo", "e1") in live_services(echo.session), 5.0)
    echo.kill("echo")
    assert _wait_for(lambda: ("echo", "e1") not in live_services(echo.session))
    with pytest.raises(ServiceUnavailable):
        request_sync(echo.session, "objscan/test/e1/echo", Ok(), timeout=2)
