"""``objscan bench real``: real sensor data, judged without ground truth.

1. **sequence variants** (``variants``): each imported (``objscan import``: turns estimated or a step given,
   solved over the view graph with the loop) then reconstructed (``objscan reconstruct``), and judged on
   itself: ``loop_deg`` (the model's loop closure, all pair transforms composed; when the model set a pair or
   a view aside, the loop over the views it kept: the pairs it kept, and ICP of the views as posed only where no
   kept pair links two kept neighbours, ``_real_loop.py``; None when such neighbours share too little to
   measure), ``worst_view_agreement`` (of a kept view's points with
   another kept view's point within 10 mm, the share within 3 mm; the worst view),
   ``status``: ``closed`` (loop <= 3 deg and every view >= 80 %), ``unsure`` (the import said so, with the
   reason; its model must not be accepted), ``missed`` (neither: a failure), ``refused`` (too few usable
   frames). The variants:

   - ``castard_every{1,2,3}``: the hand-turned box before a fixed D415 (``../shared/data/real_sequences``),
     every frame / every 2nd / every 3rd (~19 / 38 / 57 degrees a step);
   - ``kleenex_every{1,2,3}``: the tissue box on a turntable before a PrimeSense (~15 / 30 / 45 degrees);
   - ``twin_step{15,30,45,60}``: the twin's fixed-camera turntable (``sim/turntable.py``, the milk carton, D435
     noise), hand-turn jitter of 3 degrees a view, turns estimated; ``twin_step45_given``: the step given
     (45 degrees, stated to 3 degrees), direction unknown;
   - ``twin_symmetric_cup``: the harsh set's cup (a body of revolution with a colour band all round), 30 degree
     steps: its turn cannot be told, so it must come out ``unsure``;
   - ``castard_missing``: castard with depth images of three frames deleted (colour without a partner) and two
     frames removed at random (seeded): the usable frames are imported.

   ``castard``: the every-frame castard figures in detail (focal self-calibration, pair paths, picture).
2. **focal self-calibration on the twin**: a 12 x 30 deg turntable sequence of the milk carton rendered
   with fx = 615 (``sim/turntable.py``), its intrinsics.json written with fx x 0.95 / x 1 / x 1.05; the
   import must find 615 again (``importer/selfcal.py``).
3. **isolation on the real single frames** of ``../shared/data/rgbd`` (GraspNet RealSense, UOC tabletop):
   one cluster on the table per frame, with the camera pose unknown.

``quick`` runs one dynamic configuration (``no_region``) instead of the automatic choice, the variants
``castard_every3``, ``kleenex_every3``, ``twin_step45``, ``twin_symmetric_cup`` and ``castard_missing`` only,
and the twin focal check at x 0.95 only. ``OBJSCAN_BENCH_REAL_VARIANTS`` (comma-separated names) picks the
variants to run.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench._real_loop import kept_views, model_loop
from common.session_folder import MODEL_FILE

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
CASTARD_INTRINSICS = "597.522,597.522,312.885,239.870"  # from the sequence's README (D415 color stream)
KLEENEX_INTRINSICS = "570.3,570.3,320,240"  # the dataset authors' constants (the sequence's README)
LOOP_DEG, AGREEMENT = 3.0, 0.8  # a variant closes within this loop with every view agreeing at least this
OUT = Path("/tmp/objscan_bench_real")


def run_sequence(name: str, source: Path, intrinsics: str | None, quick: bool, out_root: Path = OUT,
                 picture: bool = False, **import_options: Any) -> dict[str, Any]:
    """Import ``source``, reconstruct it, and judge the model on itself (see the module doc)."""

    from services.importer.errors import ImportError_
    from services.importer.session import ImportConfig, import_sequence
    from services.importer.sources import parse_intrinsics
    from services.registration.api import DynamicConfig, reconstruct

    session, model_dir = out_root / f"{name}_session", out_root / f"{name}_model"
    shutil.rmtree(session, ignore_errors=True)
    t0 = time.perf_counter()
    try:
        imp = import_sequence(source, session, parse_intrinsics(intrinsics) if intrinsics else None,
                              ImportConfig(object_name=name, **import_options))
    except ImportError_ as exc:
        return {"status": "refused", "reason": f"[{exc.code}] {exc.message}", "loop_deg": None,
                "worst_view_agreement": None, "seconds": round(time.perf_counter() - t0, 1)}
    t_import = time.perf_counter() - t0
    turns = imp["turns"]
    loop = turns.get("loop", {})
    row: dict[str, Any] = {
        "views": imp["views"], "frames": imp["frames"], "skipped": imp["skipped_count"],
        "import_status": turns["status"], "import_reasons": loop.get("reasons", []),
        "unsure_pairs": loop.get("unsure_pairs", []), "loop_closes": loop.get("loop_closes"),
        "closing": loop.get("closing"), "solved_total_turn_deg": loop.get("total_turn_deg"),
        "estimated_total_turn_deg": round(float(np.sum(turns["pair_turn_deg"])), 2),
        "turn_direction": f"{turns['direction']} ({turns['direction_source']})",
        "focal_applied": imp["focal_calibration"]["applied"], "focal_reason": imp["focal_calibration"]["reason"],
    }
    dyn = DynamicConfig(configuration="no_region") if quick else DynamicConfig()
    report = reconstruct(session, model_dir, workers=1, dynamic=dyn)
    model = report["model"]
    row["accepted"], row["why"] = report.get("accepted"), report.get("why")
    if "error" in model:
        row.update(loop_deg=None, worst_view_agreement=None, error=model["error"])
    else:
        row.update(model_figures(model, model_dir, report.get("views")))
        if picture:
            row["picture"] = _picture(model_dir / MODEL_FILE, model_dir / "model.png").name
    row["status"], row["reason"] = judge(row)
    row.update(import_seconds=round(t_import, 1), total_seconds=round(time.perf_counter() - t0, 1),
               session=session.name, imported=imp)  # by name: the folder is this machine's
    return row


def model_figures(model: dict[str, Any], model_dir: Path, views: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """A reconstructed model judged on itself: its loop (``_real_loop.model_loop``: over the views it kept, with
    the reconstruct report's per-view entries ``views``) and how well each kept view agrees with the others
    (``view_agreement``), from ``model_dir/views``."""
    import open3d as o3d

    from services.registration.api import view_agreement

    posed, kept = [], set(kept_views(model))  # a view the model left out is not in it: not judged
    for k, T in zip(model["views_used"], model["T_model_view"], strict=True):
        if k not in kept:
            continue
        pcd = o3d.io.read_point_cloud(str(model_dir / "views" / f"view_{k:02d}.ply")).voxel_down_sample(0.002)
        T = np.asarray(T)
        posed.append(np.asarray(pcd.points) @ T[:3, :3].T + T[:3, 3])
    scores = [a["agreement"] for a in view_agreement(posed) if a["agreement"] is not None]
    paths: dict[str, int] = {}
    for e in model["edges"]:
        paths[e["path"]] = paths.get(e["path"], 0) + 1
    loop = model_loop(model, model_dir / "views", views)
    return dict(loop_deg=loop["rotation_deg"], loop_translation_mm=loop["translation_mm"], loop_over=loop["over"],
                **{k: loop[k] for k in ("set_aside", "gaps", "all_pairs_deg", "steps") if k in loop},
                worst_view_agreement=min(scores) if scores else None,
                mean_view_agreement=float(np.mean(scores)) if scores else None,
                agreement_per_view=[round(a, 3) for a in scores], edge_paths=paths,
                configuration=model["configuration"], min_posed_fitness=model["consistency"]["min_posed_fitness"],
                model_points=model["points"])


def judge(row: dict[str, Any]) -> tuple[str, str]:
    """``closed`` / ``unsure`` / ``missed`` and why (an unsure import whose model claims acceptance is a miss)."""
    loop, worst = row.get("loop_deg"), row.get("worst_view_agreement")
    if row.get("import_status") == "unsure":
        if row.get("accepted"):
            return "missed", "the import is unsure but the model claims to be accepted"
        return "unsure", "; ".join(row.get("import_reasons") or ["unsure"])
    if loop is not None and worst is not None and loop <= LOOP_DEG and worst >= AGREEMENT:
        return "closed", f"loop {loop:.2f} deg, worst view {worst:.1%}"
    if loop is None and row.get("gaps"):
        where = ", ".join(f"{g['from']} -> {g['to']} (overlap {g['overlap']:.2f})" for g in row["gaps"])
        return "missed", (f"the loop over the views the model kept is not measured: {where} share too little; "
                          "only the full-turn constraint places them")
    if loop is None:
        return "missed", f"no model: {row.get('error', {}).get('message', '')}"
    return "missed", f"loop {loop:.2f} deg (<= {LOOP_DEG:g}), worst view {worst:.1%} (>= {AGREEMENT:.0%})"


def castard(quick: bool, out_root: Path = OUT) -> dict[str, Any]:
    """The every-frame castard sequence, with the focal self-calibration's figures."""
    row = run_sequence("castard_every1", DATA / "real_sequences" / "castard_d415", CASTARD_INTRINSICS, quick,
                       out_root, picture=True)
    return castard_detail(row)


def castard_detail(row: dict[str, Any]) -> dict[str, Any]:
    """The focal self-calibration's figures of an imported row, beside the row's own."""
    imp = row.get("imported")
    if imp is None:
        return row
    focal = imp["focal_calibration"]
    return {**{k: v for k, v in row.items() if k != "imported"},
            "focal_scale": focal["scale"], "fx_used": focal["fx_after"],
            "focal_loop_yaw_before_after_deg": [focal["loop_yaw_before_deg"], focal["loop_yaw_after_deg"]],
            "camera_height_m": imp["base_frame"]["camera_height_m"]}


def _thinned(seq: Path, dest: Path, drop_depth: int, drop_frames: int, seed: int) -> Path:
    """A copy of the castard layout with ``drop_depth`` depth images and ``drop_frames`` whole frames removed
    at random (seeded): a folder with missing partners and gaps in the turn."""
    shutil.rmtree(dest, ignore_errors=True)
    shutil.copytree(seq, dest)
    numbers = sorted(int(p.stem.removeprefix("align_test_depth")) for p in (dest / "depth").glob("*.png"))
    rng = np.random.default_rng(seed)
    picks = rng.choice(numbers[1:-1], drop_depth + drop_frames, replace=False)  # keep the ends: the loop
    for n in picks[:drop_depth]:
        (dest / "depth" / f"align_test_depth{n}.png").unlink()
    for n in picks[drop_depth:]:
        (dest / "depth" / f"align_test_depth{n}.png").unlink()
        (dest / "rgb" / f"align_test{n}.png").unlink()
    return dest


def _twin(name: str, out_root: Path, object_name: str, step: float, jitter: float) -> Path:
    """A twin turntable sequence (fixed camera, D435 noise) rendered into ``out_root/name``."""
    from services.sim.turntable import TurntableSpec, render_turntable

    seq = out_root / name
    shutil.rmtree(seq, ignore_errors=True)
    views = int(round(360.0 / step))
    render_turntable(TurntableSpec(object_name=object_name, views=views, step_deg=step, turn_jitter_deg=jitter,
                                   seed=int(step)), seq)
    return seq


def variant_names(quick: bool) -> list[str]:
    """The variants this run measures (see the module doc)."""
    chosen = os.environ.get("OBJSCAN_BENCH_REAL_VARIANTS")
    if chosen:
        return [v.strip() for v in chosen.split(",") if v.strip()]
    if quick:
        return ["castard_every3", "kleenex_every3", "twin_step45", "twin_symmetric_cup", "castard_missing"]
    return ["castard_every1", "castard_every2", "castard_every3", "kleenex_every1", "kleenex_every2",
            "kleenex_every3", "twin_step15", "twin_step30", "twin_step45", "twin_step60", "twin_step45_given",
            "twin_symmetric_cup", "castard_missing"]


def run_variant(name: str, quick: bool, out_root: Path = OUT) -> dict[str, Any]:
    """One variant's row (``run_sequence``), its source made first when it is rendered or thinned."""
    castard_seq = DATA / "real_sequences" / "castard_d415"
    if name.startswith("castard_every"):
        return run_sequence(name, castard_seq, CASTARD_INTRINSICS, quick, out_root,
                            every=int(name.removeprefix("castard_every")))
    if name.startswith("kleenex_every"):
        return run_sequence(name, DATA / "real_sequences" / "kleenex_primesense", KLEENEX_INTRINSICS, quick,
                            out_root, every=int(name.removeprefix("kleenex_every")))
    if name == "castard_missing":
        seq = _thinned(castard_seq, out_root / "castard_missing_folder", drop_depth=3, drop_frames=2, seed=0)
        return run_sequence(name, seq, CASTARD_INTRINSICS, quick, out_root)
    if name == "twin_step45_given":
        seq = _twin(name + "_folder", out_root, "milk", 45.0, 1.5)
        return run_sequence(name, seq, None, quick, out_root, turn_step_deg=45.0, turn_step_sigma_deg=3.0)
    if name.startswith("twin_step"):
        step = float(name.removeprefix("twin_step"))
        return run_sequence(name, _twin(name + "_folder", out_root, "milk", step, 3.0), None, quick, out_root)
    if name == "twin_symmetric_cup":
        from bench.harsh_set import write_mesh

        mesh = write_mesh("cup", out_root / "meshes")
        return run_sequence(name, _twin(name + "_folder", out_root, str(mesh), 30.0, 3.0), None, quick, out_root)
    raise ValueError(f"unknown variant {name!r}")


def variants(quick: bool, out_root: Path = OUT) -> dict[str, dict[str, Any]]:
    """Every variant's row; the keys the issue names first (``loop_deg``, ``worst_view_agreement``, ``status``)."""
    out = {}
    for name in variant_names(quick):
        try:
            row = run_variant(name, quick, out_root)
        except Exception as exc:  # noqa: BLE001 - a bench: one variant's crash is its row, the others go on
            row = {"status": "error", "reason": f"{type(exc).__name__}: {exc}", "loop_deg": None,
                   "worst_view_agreement": None}
        row = castard_detail(row) if name == "castard_every1" else row  # the focal figures, from its import
        row.pop("imported", None)
        out[name] = {"loop_deg": row.get("loop_deg"), "worst_view_agreement": row.get("worst_view_agreement"),
                     "status": row["status"], **row}
        print(f"{name}: {row['status']} ({row.get('reason', '')})", flush=True)
        # a long run keeps what it has: the rows so far, beside the sessions (the result is written at the end)
        (out_root / "variants_so_far.json").write_text(json.dumps(out, indent=1, default=float))
    return out


def _picture(ply: Path, png: Path) -> Path:
    """Three views of the model side by side (front, side, above), for BENCHMARKS.md and docs."""
    import open3d as o3d
    from PIL import Image

    from services.report.raster import orbit_camera, render_points

    pcd = o3d.io.read_point_cloud(str(ply))
    xyz, rgb = np.asarray(pcd.points), np.asarray(pcd.colors) * 255.0
    nrm = np.asarray(pcd.normals) if pcd.has_normals() else None
    c = xyz.mean(axis=0)
    r = float(np.percentile(np.linalg.norm(xyz - c, axis=1), 99))
    tiles = [render_points(xyz, rgb, orbit_camera(c, r, az, el, 360, 420, 0.9), normals=nrm, radius_px=1)
             for az, el in ((180, 15), (90, 15), (225, 60))]
    Image.fromarray(np.concatenate(tiles, axis=1)).save(png)
    return png


def single_frames() -> dict[str, Any]:
    """Isolation on the real single frames (camera pose unknown: identity, up found from the data)."""
    from PIL import Image

    from common.errors import ObjscanError
    from common.messages import Intrinsics, RGBDFrame
    from services.registration.api import StaticConfig, register_view

    d = DATA / "rgbd" / "tabletop_uoc"
    p = json.loads((d / "camera_params.json").read_text())
    cfg = StaticConfig(expected_up=None, depth_max=2.0)
    rows = []
    for color_path in sorted(d.glob("*-color.png")):
        stem = color_path.name.removesuffix("-color.png")
        color = np.asarray(Image.open(color_path).convert("RGB"))
        depth = np.asarray(Image.open(d / f"{stem}-depth.png")).astype(np.uint16)
        K = Intrinsics(width=color.shape[1], height=color.shape[0], fx=p["fx"], fy=p["fy"], cx=p["x_offset"],
                       cy=p["y_offset"])
        frame = RGBDFrame(color=color, depth=depth, depth_scale=0.001, intrinsics=K, T_base_camera=np.eye(4))
        try:
            r = register_view([frame], cfg)
            rows.append({"frame": stem, "ok": True, "points": len(r.object_cloud),
                         "height_mm": round(1000 * r.object_height, 1), "clusters": r.n_clusters})
        except ObjscanError as exc:
            rows.append({"frame": stem, "ok": False, "code": exc.code})
    return {"frames": len(rows), "isolated": sum(r["ok"] for r in rows), "per_frame": rows}


def twin_focal(written_scales: tuple[float, ...], out_root: Path = OUT) -> list[dict[str, Any]]:
    """Import twin turntable sequences whose intrinsics file is off by each of ``written_scales``."""
    from services.importer.session import import_sequence
    from services.sim.turntable import TurntableSpec, render_turntable

    rows = []
    for w in written_scales:
        seq, session = out_root / f"twin_fx{w:.2f}", out_root / f"twin_fx{w:.2f}_session"
        shutil.rmtree(session, ignore_errors=True)  # an import refuses a non-empty folder: an earlier run's
        truth = render_turntable(TurntableSpec(object_name="milk", views=12, step_deg=30.0), seq, w)
        t0 = time.perf_counter()
        fc = import_sequence(seq, session)["focal_calibration"]
        fx_true = truth["intrinsics"]["fx"]
        rows.append({"written_scale": w, "fx_true": fx_true, "fx_written": fc["fx_before"], "fx_found": fc["fx_after"],
                     "error_pct": round(100.0 * (fc["fx_after"] / fx_true - 1.0), 3), "applied": fc["applied"],
                     "loop_yaw_before_deg": fc["loop_yaw_before_deg"], "loop_yaw_after_deg": fc["loop_yaw_after_deg"],
                     "search_seconds": fc["seconds"], "import_seconds": round(time.perf_counter() - t0, 1)})
    return rows


def run(quick: bool = False) -> dict[str, Any]:
    OUT.mkdir(parents=True, exist_ok=True)
    scales = (0.95,) if quick else (0.95, 1.0, 1.05)
    rows = variants(quick)
    counts = {s: sum(r["status"] == s for r in rows.values())
              for s in ("closed", "unsure", "missed", "refused", "error")}
    return {"quick": quick, "variants": rows, "variant_counts": counts, "castard": rows.get("castard_every1"),
            "twin_focal": twin_focal(scales), "tabletop_uoc": single_frames()}
