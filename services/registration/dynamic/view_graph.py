"""Pose-graph optimisation over all 12 pair edges with the loop closure (beyond the paper).

Instead of dropping the weakest of the 12 transforms, keep them all and let Open3D's global
optimisation (Levenberg-Marquardt, Choi et al. 2015 line process) spread the loop-closure error over
the edges in proportion to how well each is constrained (information matrix from the point clouds),
pruning an edge that does not agree with the rest.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from services.registration.dynamic.combine import CombineConfig, CombineResult, chain_poses
from services.registration.dynamic.pair import PairResult
from services.registration.dynamic.preprocess import Prepared
from services.registration.dynamic.views import DynamicRegistrationError

reg = o3d.pipelines.registration


def build_pose_graph(prep: Prepared, results: list[PairResult], cfg: CombineConfig) -> reg.PoseGraph:
    """Nodes initialised by chaining the sequential edges; one edge per pair result."""
    n = len(prep.views)
    loop_edges = {r.index for r in results if abs(r.source_view - r.target_view) != 1}
    try:
        poses = chain_poses(n, results, skip=loop_edges)
    except DynamicRegistrationError:  # a neighbour edge was left out (implausible): the loop edge connects
        poses = chain_poses(n, results)
    graph = reg.PoseGraph()
    for P in poses:
        graph.nodes.append(reg.PoseGraphNode(P))
    clouds = [v.reduced.downsampled(cfg.consistency_voxel).to_o3d() for v in prep.views]
    for r in results:
        info = reg.get_information_matrix_from_point_clouds(
            clouds[r.source_view], clouds[r.target_view], cfg.pg_max_correspondence, r.T)
        uncertain = cfg.pg_uncertain == "all" or r.index in loop_edges
        graph.edges.append(reg.PoseGraphEdge(r.source_view, r.target_view, r.T, info, uncertain=uncertain))
    return graph


def optimise_pose_graph(prep: Prepared, results: list[PairResult], cfg: CombineConfig) -> CombineResult:
    """Optimise the graph; poses map each pre-processed view into the model frame (view 0 fixed)."""
    graph = build_pose_graph(prep, results, cfg)
    option = reg.GlobalOptimizationOption(max_correspondence_distance=cfg.pg_max_correspondence,
                                          edge_prune_threshold=cfg.pg_edge_prune_threshold,
                                          preference_loop_closure=1.0, reference_node=0)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                reg.GlobalOptimizationConvergenceCriteria(), option)
    P0_inv = np.linalg.inv(np.asarray(graph.nodes[0].pose))
    poses = [P0_inv @ np.asarray(node.pose) for node in graph.nodes]
    kept = len(graph.edges)
    return CombineResult(poses, "pose_graph", None, {"edges_kept": kept, "edges_in": len(results)})
