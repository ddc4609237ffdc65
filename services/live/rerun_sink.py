"""Draws scene events into a Rerun recording: spawned viewer (``--rerun``) or an ``.rrd`` file (``--rerun-save``).

Entity layout (``base`` is the arm base on the table, z up; every pose is ``T_base_*``):

- ``world/camera``: the believed camera pose; ``world/camera/image`` its pinhole, with ``color`` and
  ``depth`` images below it (so the frustum and the images sit where the camera was);
- ``world/papras_6dof/...``: the PAPRAS links from its URDF (meshes logged once, static, by Rerun's URDF
  loader), moved by one transform per joint (``world/arm/joints/<joint>``) from the joint states;
- ``world/views/NN/object``: the isolated object cloud of view NN (``world/views/locate/object`` for the
  locate step); ``world/grasps/candidates`` the planned grasps (approach arrows), ``world/grasps/chosen``
  the grasp the arm closed on; ``world/model_preview`` the growing model (views placed by their commanded
  turns, as the dynamic registration starts), cleared when ``world/model``, the registered model, arrives;
- ``status``: the orchestrator's state as a text log.

Time: the ``time`` timeline (wall clock of each event) and the ``view`` sequence.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.urdf as rru

from common.messages import PointCloud
from services.arm.robot import URDF_PATH
from services.live import scene
from services.live.urdf_joints import joint_transforms, load_joints

log = logging.getLogger("objscan.live")
APP_ID = "objscan"
ARM = "world/arm"
URDF_ROOT_FRAME = "world"  # the PAPRAS URDF's root link, identical to ``base`` (robot1/link1 at the origin)


def viewer_executable() -> Path:
    """The Rerun viewer inside the installed rerun-sdk wheel (``rerun_cli/rerun``): found even when the
    venv's ``bin`` is not on PATH (``.venv/bin/objscan`` run without activating the venv)."""
    import rerun_cli

    return Path(rerun_cli.__file__).resolve().parent / "rerun"


def _a(x: object, dtype: str) -> np.ndarray:
    """An aligned, C-contiguous copy-if-needed: decoded arrays point into the msgpack buffer at any offset,
    and Rerun's Arrow import aborts the whole process (a Rust panic, not an exception) on unaligned memory."""
    return np.require(np.asarray(x, dtype=dtype), requirements=["C", "A"])


def _points(cloud: PointCloud, default_rgb: tuple[int, int, int]) -> rr.Points3D:
    xyz = _a(cloud.xyz, "f4")
    rgb = _a(cloud.rgb, "u1") if cloud.rgb is not None and len(cloud.rgb) == len(xyz) else None
    return rr.Points3D(xyz, colors=rgb if rgb is not None else [default_rgb], radii=0.0015)


class RerunSink:
    """One Rerun recording stream fed with scene events; ``close()`` flushes (and ends the file)."""

    def __init__(self, *, save: str | Path | None = None, spawn: bool = False, recording_id: str | None = None,
                 urdf: str | Path = URDF_PATH):
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
        sinks: list[rr.FileSink | rr.GrpcSink] = []
        if save is not None:
            Path(save).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(save)))
        if spawn:
            # the viewer binary ships in the rerun-sdk wheel (rerun_cli); nothing is downloaded
            rr.spawn(connect=False, executable_path=str(viewer_executable()), hide_welcome_screen=True,
                     recording=self.rec)
            sinks.append(rr.GrpcSink())  # the spawned viewer's default address
        if sinks:
            self.rec.set_sinks(*sinks)  # both at once when asked for both
        self.joints = load_joints(urdf)
        self.view = -1
        self._static(urdf)

    def _static(self, urdf: str | Path) -> None:
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rru.UrdfTree.from_file_path(urdf, "world").log_urdf_to_recording(rec)  # world/papras_6dof/...
        # the URDF's named frames hang off the ``world`` entity's implicit frame
        rec.log(f"{ARM}/root", rr.Transform3D(parent_frame="tf#/world", child_frame=URDF_ROOT_FRAME), static=True)
        self._joints(0.0, [], np.zeros(0), static=True)

    def _time(self, t: float) -> None:
        self.rec.set_time("time", timestamp=float(t))
        self.rec.set_time("view", sequence=max(self.view, 0))

    def _joints(self, t: float, names: list[str], q: np.ndarray, *, static: bool = False) -> None:
        for joint, T in joint_transforms(self.joints, names, q, include_fixed=static):
            self.rec.log(f"{ARM}/joints/{rr.escape_entity_path_part(joint.name)}",
                         rr.Transform3D(translation=_a(T[:3, 3], "f8"), mat3x3=_a(T[:3, :3], "f8"),
                                        parent_frame=joint.parent,
                                        child_frame=joint.child), static=static)

    def handle(self, event: scene.Event) -> None:
        """Log one event at its time."""
        rec = self.rec
        if isinstance(event, scene.ViewCloud):
            self.view = event.view
        self._time(event.t)
        if isinstance(event, scene.CameraFrame):
            f = event.frame
            i = f.intrinsics
            T = _a(f.T_base_camera, "f8")
            rec.log("world/camera", rr.Transform3D(translation=T[:3, 3].copy(), mat3x3=T[:3, :3].copy()))
            rec.log("world/camera/image", rr.Pinhole(focal_length=[i.fx, i.fy], principal_point=[i.cx, i.cy],
                                                     width=i.width, height=i.height,
                                                     camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.1))
            rec.log("world/camera/image/color", rr.Image(_a(f.color, "u1"), color_model="RGB"))
            rec.log("world/camera/image/depth", rr.DepthImage(_a(f.depth, "u2"),
                                                              meter=1.0 / float(f.depth_scale)))
        elif isinstance(event, scene.ArmState):
            self._joints(event.t, event.names, event.q)
        elif isinstance(event, scene.ViewCloud):
            name = "locate" if event.view < 0 else f"{event.view:02d}"
            rec.log(f"world/views/{name}/object", _points(event.cloud, (120, 170, 255)))
        elif isinstance(event, scene.GraspCandidates):
            P = _a(event.poses, "f8")
            approach = P[:, :3, 0] * 0.05  # gripper x = approach direction (docs/conventions.md)
            rec.log("world/grasps/candidates", rr.Arrows3D(origins=P[:, :3, 3] - approach, vectors=approach,
                                                           colors=[(255, 200, 0)], labels=event.kinds))
        elif isinstance(event, scene.ChosenGrasp):
            T = _a(event.pose, "f8")
            rec.log("world/grasps/chosen", rr.Transform3D(translation=T[:3, 3].copy(), mat3x3=T[:3, :3].copy()),
                    rr.TransformAxes3D(axis_length=0.06))
        elif isinstance(event, scene.ModelPreview):
            rec.log("world/model_preview", rr.Points3D(_a(event.xyz, "f4"), colors=_a(event.rgb, "u1"), radii=0.0015))
        elif isinstance(event, scene.Model):
            rec.log("world/model", _points(event.cloud, (230, 230, 230)))
            rec.log("world/model_preview", rr.Clear(recursive=False))  # the registered model replaces it
        elif isinstance(event, scene.Status):
            s = event.info
            rec.log("status", rr.TextLog(f"view {s.get('view')}: {s.get('state')} ({s.get('views_done', 0)}/"
                                         f"{s.get('views')} views) {s.get('status')}"))

    def close(self) -> None:
        try:
            self.rec.flush()
        except RuntimeError as exc:  # the spawned viewer was closed (or could not open a window): not a failure
            log.warning("Rerun viewer went away before the end: %s", exc)
        self.rec.disconnect()
