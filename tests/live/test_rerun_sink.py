"""The Rerun sink, read back with the Rerun SDK: every kind of scene event lands on its entity."""

from __future__ import annotations

import numpy as np
from rerun.chunk import RrdReader

from services.live.feed import LiveView
from services.live.rerun_sink import RerunSink
from tests.live.rrd_entities import rrd_entities
from tests.live.scan_messages import feed, over_the_wire, scan_items


def test_a_short_scan_streams_frames_poses_clouds_grasps_arm_and_model(tmp_path):
    path = tmp_path / "scan.rrd"
    view = LiveView([RerunSink(save=path)])
    feed(view, over_the_wire(scan_items()))
    view.close()
    ents = rrd_entities(path)
    # frames: colour and depth images under the camera's pinhole, the camera's pose per frame
    assert ents["/world/camera/image/color"]["Image:buffer"] == 2
    assert ents["/world/camera/image/depth"]["DepthImage:buffer"] == 2
    assert ents["/world/camera/image"]["Pinhole:image_from_camera"] == 2
    assert ents["/world/camera"]["Transform3D:translation"] == 2
    # clouds per view, grasp candidates and the chosen grasp, the model
    assert ents["/world/views/00/object"]["Points3D:positions"] == 1
    assert ents["/world/views/01/object"]["Points3D:positions"] == 1
    assert ents["/world/grasps/candidates"]["Arrows3D:vectors"] == 2
    assert ents["/world/grasps/chosen"]["Transform3D:translation"] == 2
    assert ents["/world/model"]["Points3D:positions"] == 1
    assert ents["/world/model_preview"]["Points3D:positions"] == 2  # after view 0, then views 0 and 1
    assert ents["/world/model_preview"]["Clear:is_recursive"] == 1  # cleared when the model arrives
    # the arm: URDF meshes (static) and a transform per joint per state: the static zero pose, then
    # 2 joint-state samples and 4 move results
    meshes = [e for e in ents if e.startswith("/world/papras_6dof/visual_geometries/")]
    assert len(meshes) >= 8 and all("Asset3D:blob" in ents[e] or "Boxes3D:half_sizes" in ents[e] for e in meshes)
    assert sum("Asset3D:blob" in ents[e] for e in meshes) >= 8  # link1..6, end link, gripper: STL meshes
    j1 = ents["/world/arm/joints/robot1\\/joint1"]
    assert j1["Transform3D:parent_frame"] == 1 + 6 and j1["Transform3D:child_frame"] == 7
    assert ents["/status"]["TextLog:text"] == 3
    assert RrdReader(path).recordings()[0].application_id == "objscan"


def test_joint_transforms_connect_the_mesh_frames_to_the_world(tmp_path):
    """Each link mesh is drawn in its link's frame; that frame must be a joint's child, and the URDF root must
    hang off the ``world`` entity, or Rerun would draw the arm nowhere."""
    path = tmp_path / "arm.rrd"
    RerunSink(save=path).close()
    mesh_frames, parents, children = set(), set(), set()
    for chunk in RrdReader(path).store().stream():
        rb = chunk.to_record_batch()
        names = rb.schema.names
        if "CoordinateFrame:frame" in names and "visual_geometries" in chunk.entity_path:
            mesh_frames.update(np.ravel(rb.column("CoordinateFrame:frame").to_pylist()))
        if "Transform3D:child_frame" in names:
            children.update(np.ravel(rb.column("Transform3D:child_frame").to_pylist()))
            parents.update(np.ravel(rb.column("Transform3D:parent_frame").to_pylist()))
    assert "robot1/link3" in mesh_frames and mesh_frames <= children | {"world"}, mesh_frames - children
    assert "tf#/world" in parents and "world" in children


def test_logged_values_are_the_messages_values(tmp_path):
    """Not just entities: the camera pose, image size and cloud sizes are what the messages held."""
    path = tmp_path / "scan.rrd"
    view = LiveView([RerunSink(save=path)])
    items = scan_items()
    feed(view, items)
    view.close()
    cols: dict[str, list] = {}
    for chunk in RrdReader(path).store().stream():
        rb = chunk.to_record_batch()
        for name in (n for n in rb.schema.names if ":" in n):  # components, not timelines
            if chunk.entity_path in ("/world/camera", "/world/model", "/world/camera/image"):
                cols.setdefault(f"{chunk.entity_path}:{name}", []).extend(rb.column(name).to_pylist())
    translations = [np.ravel(v) for v in cols["/world/camera:Transform3D:translation"]]
    frames = [it[4] for it in items if type(it[4]).__name__ == "RGBDFrame"]
    assert np.allclose(sorted(tr[2] for tr in translations), sorted(f.T_base_camera[2, 3] for f in frames))
    assert len(cols["/world/model:Points3D:positions"][0]) == 500
    assert np.allclose(np.ravel(cols["/world/camera/image:Pinhole:resolution"][0]), [64, 48])
