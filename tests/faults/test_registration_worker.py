"""A fresh registration worker must decode the pair jobs other workers send it.

Found by the fault-injection tests: with two workers, the model stage failed with
``unknown message type 'PairJobMessage'`` because that type is registered only once a worker has imported
``services.registration.pair_wire`` (lazily, inside its handlers), while the runtime decodes the request
before calling any handler. Fixed in services/registration/service.py: ``pair_wire`` is imported at module level.
"""

from __future__ import annotations

import numpy as np

from common.client import live_services
from common.codec import decode
from common.launcher import ProcessSpec
from common.messages import Error, PointCloud
from services.registration.api import PairJobMessage


def _job() -> PairJobMessage:
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-0.05, 0.05, (200, 3)).astype(np.float32) + np.float32([0.6, 0, 0.1])
    cloud = PointCloud(xyz=xyz, rgb=np.full((200, 3), 128, np.uint8), normals=None)
    return PairJobMessage(index=0, source_view=0, target_view=1, source=cloud, target=cloud,
                          center=np.array([0.6, 0.0, 0.0]), axis=np.array([0.0, 0.0, 1.0]), prior=np.eye(4))


def test_fresh_worker_decodes_a_pair_job(service_group):
    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=120)
    (instance,) = [i for s, i in live_services(service_group.session) if s == "registration"]
    replies = list(service_group.session.get(f"objscan/registration/worker/{instance}/pair",
                                             payload=_job().encode(), timeout=60))
    assert len(replies) == 1
    reply = decode(replies[0].ok.payload.to_bytes())
    assert not (isinstance(reply, Error) and reply.code == "unknown_type"), reply.message


def test_shim_worker_decodes_a_pair_job(service_group):
    """The fault tests' worker (tests/faults/registration_worker.py) gets past decoding."""
    service_group.launch([ProcessSpec("tests.faults.registration_worker", [], service="registration")],
                         timeout=120)
    (instance,) = [i for s, i in live_services(service_group.session) if s == "registration"]
    replies = list(service_group.session.get(f"objscan/registration/worker/{instance}/pair",
                                             payload=_job().encode(), timeout=120))
    assert len(replies) == 1
    reply = decode(replies[0].ok.payload.to_bytes())
    assert not (isinstance(reply, Error) and reply.code == "unknown_type"), reply.message
