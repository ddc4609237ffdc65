"""The 'operator machine' of the multi-namespace test (runs inside its own network namespace).

It coordinates a dynamic registration whose pair jobs go to the registration workers of the other
"machines" (``services.registration.dynamic_face.distributed_map``, the coordinator's own code), tells the
test (one stdout line, ``PARTITION <instance>``) when the worker to cut off is busy with a job, then sends
``arm/stop`` every 50 ms while the partition lasts and prints one JSON line with what happened.
"""

from __future__ import annotations

import json
import sys
import threading
import time

from common import keys
from common.client import live_services, request_sync
from common.errors import ObjscanError
from common.messages import Health, Ok
from common.zenoh_config import ZenohSettings, open_session


def main(victim: str, views: int, go_file: str) -> None:
    from pathlib import Path

    from services.registration.api import build_model, views_from_results
    from services.registration.dynamic_face import distributed_map
    from tests.registration.test_distributed_workers import _requests

    session = open_session(ZenohSettings.from_env())
    deadline = time.monotonic() + 120
    while not {("registration", "wA"), ("registration", victim), ("arm", "arm0")} <= set(live_services(session)):
        if time.monotonic() > deadline:
            raise SystemExit(f"cell not live: {live_services(session)}")
        time.sleep(0.5)
    request = _requests(views)
    dyn_views = views_from_results(request.views, request.turns_deg)
    stats: dict = {}
    result: dict = {}

    def register() -> None:
        try:
            model = build_model(dyn_views, None, distributed_map(session, stats))
            result["points"] = len(model.xyz)
            result["figures"] = {k: v for k, v in model.to_json().items() if k in ("loop_closure", "pairs")}
        except BaseException as exc:  # noqa: BLE001 - reported
            result["error"] = repr(exc)

    t0 = time.monotonic()
    worker = threading.Thread(target=register)
    worker.start()
    while worker.is_alive():  # wait until the victim is inside a pair job
        try:
            h = request_sync(session, keys.health("registration", victim), timeout=2)
            if isinstance(h, Health) and h.busy > 0:
                break
        except ObjscanError:
            pass
        time.sleep(0.1)
    print(f"PARTITION {victim}", flush=True)
    while not Path(go_file).exists():
        time.sleep(0.05)
    stops: list[float] = []
    while worker.is_alive() and len(stops) < 400:
        s0 = time.perf_counter()
        try:
            ok = isinstance(request_sync(session, keys.arm(keys.DEFAULT_ROBOT, "stop"), timeout=5), Ok)
        except ObjscanError:
            ok = False
        stops.append((time.perf_counter() - s0) * 1e3 if ok else -1.0)
        time.sleep(0.05)
    worker.join()
    print(json.dumps({"stats": stats, "result": result, "stops_ms": stops, "seconds": time.monotonic() - t0}),
          flush=True)
    session.close()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3])
