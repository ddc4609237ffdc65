"""Pose graph of the scans of one view (the paper's last step before PC_global).

Nodes are the scans, node 0 is the anchor (its pose is fixed); every registered pair is an edge. With three
scans there is one loop (0-1, 1-2, 0-2), so the optimiser spreads the pairwise disagreement instead of
letting one bad pair decide a scan's pose alone.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

reg = o3d.pipelines.registration


def optimise(
    n_nodes: int,
    edges: list[tuple[int, int, np.ndarray, np.ndarray]],
    initial: list[np.ndarray],
    max_corr: float,
) -> list[np.ndarray]:
    """Optimise node poses (node -> anchor frame) given ``edges`` (source, target, T_target_source, info).

    ``T_target_source`` maps source points into the target's frame, so ``pose[source] = pose[target] @ T``.
    Returns the poses with node 0 at identity.
    """
    graph = reg.PoseGraph()
    for pose in initial:
        graph.nodes.append(reg.PoseGraphNode(np.asarray(pose, dtype=np.float64)))
    for s, t, T, info in edges:
        # edges to the anchor are the spanning tree; the others are loop closures the optimiser may prune
        # (line process) when they disagree with the rest: that is what saves a view from one bad pair
        graph.edges.append(reg.PoseGraphEdge(s, t, np.asarray(T, dtype=np.float64), np.asarray(info), uncertain=t != 0))
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=max_corr,
        edge_prune_threshold=0.25,
        preference_loop_closure=1.0,
        reference_node=0,
    )
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            graph,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )
    poses = [np.asarray(graph.nodes[i].pose).copy() for i in range(n_nodes)]
    anchor_inv = np.linalg.inv(poses[0])
    return [anchor_inv @ p for p in poses]
