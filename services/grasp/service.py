"""The grasp service's Zenoh face: ``objscan/grasp/plan`` → ranked grasps with their poses, or why none."""

from __future__ import annotations

import dataclasses

from common import keys
from common.api import GraspPlanReply, GraspRequest
from common.codec import Message
from common.errors import InvalidRequest
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.grasp.config import GraspPlannerConfig
from services.grasp.planner import plan_grasps_for_cloud


class GraspService(Service):
    name = "grasp"

    async def setup(self) -> None:
        self.config = GraspPlannerConfig()
        self.plans = 0
        self.queryable(keys.GRASP_PLAN, self.plan)

    async def plan(self, msg: Message | None, ctx: QueryContext) -> GraspPlanReply:
        if not isinstance(msg, GraspRequest):
            raise InvalidRequest("expected a GraspRequest", detail={"got": type(msg).__name__})
        config = dataclasses.replace(self.config, mode=msg.mode)
        plan = await self.run_cpu(plan_grasps_for_cloud, msg.cloud, msg.table, config)
        self.plans += 1
        summary = plan.summary()
        return GraspPlanReply(grasps=plan.to_messages(msg.cloud.frame), rejections=summary["rejections"],
                              explanation=plan.explain(), seconds=plan.timings_ms.get("total", 0.0) / 1e3)

    def health_info(self) -> dict[str, object]:
        return {"plans": self.plans}


def main() -> None:
    args = service_arg_parser("objscan grasp planning service").parse_args()
    run_service(lambda: GraspService(settings_from_args(args)))
