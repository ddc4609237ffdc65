"""``build_report``: one self-contained HTML page about an acquisition (images inlined as base64 PNG).

Sections: summary; accuracy against ground truth with a per-point error map (simulated sessions); the model
in an interactive viewer (``viewer.py``: turn and zoom, coloured by its error where ground truth is known)
and from several angles; the registration graph with per-edge fitness; per view the color images, the isolated
object rendered from the first scan's camera with the chosen grasp's contacts drawn on it, and the grasp
plans; timings per step; the decision log. Everything renders on the CPU (``raster.py``), so it works on a
headless machine. Missing parts (a failed run) are reported as missing, not as an error.
"""

from __future__ import annotations

import html
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from common.session_folder import atomic_write_bytes, read_scan_dir
from services.report.errors import ReportError
from services.report.graph import registration_graph_svg, timings_svg
from services.report.raster import RasterCamera, colormap, orbit_camera, png_data_uri, render_points
from services.report.session_data import SessionData, ViewData, ground_truth_points, load_session
from services.report.viewer import CSS as VIEWER_CSS
from services.report.viewer import MAX_POINTS as VIEWER_POINTS
from services.report.viewer import MAX_TRIANGLES as MESH_TRIANGLES
from services.report.viewer import mesh_viewer_html, viewer_html


@dataclass(frozen=True)
class ReportConfig:
    """What the page shows and at what size. ``error_vmax_mm`` fixes the error color scale (not the
    data's max) so reports of different sessions can be compared by eye; 2 mm is the tighter F-score threshold, so a
    yellow point is one the F@2mm figure counts as wrong."""

    model_angles_deg: tuple[tuple[float, float], ...] = ((-90.0, 25.0), (0.0, 25.0), (90.0, 25.0), (180.0, 25.0),
                                                          (0.0, 80.0))
    error_angles_deg: tuple[tuple[float, float], ...] = ((-90.0, 25.0), (90.0, 25.0), (180.0, 25.0))
    render_size: tuple[int, int] = (360, 300)
    thumb_side: int = 240
    max_render_points: int = 200_000
    error_vmax_mm: float = 2.0
    gt_points: int = 60_000
    seed: int = 0


def build_report(session_dir: str | Path, out: str | Path | None = None, config: ReportConfig | None = None) -> Path:
    """Write the HTML report of ``session_dir`` to ``out`` (default ``SESSION/report.html``); returns its path."""
    cfg = config or ReportConfig()
    session = load_session(session_dir)
    page = render_html(session, cfg)
    path = Path(out) if out is not None else session.path / "report.html"
    try:
        atomic_write_bytes(path, page.encode("utf-8"))
    except OSError as exc:
        raise ReportError(f"cannot write {path}: {exc}", code="io_error") from None
    return path


def render_html(session: SessionData, cfg: ReportConfig = ReportConfig()) -> str:
    """The page as a string (see the module doc for its sections)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(cfg.seed)
    errors = _model_errors(session, cfg, rng)
    sections = [_summary(session), _accuracy(session, cfg, errors), _model(session, cfg, rng, errors), _graph(session),
                _views(session, cfg), _timings(session), _decisions(session)]
    title = f"objscan report: {session.object_name}"
    footer = (f"Generated {time.strftime('%Y-%m-%d %H:%M:%S')} from {html.escape(str(session.path))} "
              f"in {time.perf_counter() - t0:.1f} s.")
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<style>{_CSS}{VIEWER_CSS}</style></head>"
            f"<body><h1>{html.escape(title)}</h1>{''.join(sections)}<footer>{footer}</footer></body></html>\n")


# ------------------------------------------------------------------------------------------------ sections
def _verdict(s: SessionData) -> str | None:
    """The dynamic stage's verdict on the model: "yes", "NO: <why>", or None for a report without one."""
    accepted = s.report.get("accepted", s.model_figures.get("accepted"))
    if accepted is None:
        return None
    return "yes" if accepted else f"NO: {s.report.get('why') or s.model_figures.get('why') or 'see report.json'}"


def _summary(s: SessionData) -> str:
    cfg = s.info.get("config") or s.journal.get("config") or {}
    acc = s.accuracy or {}
    rows = [("object", s.object_name), ("profile", s.info.get("profile") or cfg.get("profile")),
            ("seed", s.info.get("seed", cfg.get("seed"))), ("status", s.journal.get("status", "unknown")),
            ("views", f"{sum(1 for v in s.views if v.object_cloud is not None)} registered of {len(s.views)}"),
            ("model points", s.report.get("points", s.model_figures.get("points"))),
            ("configuration", s.model_figures.get("configuration")),
            ("model accepted", _verdict(s)),
            ("views left out", ", ".join(str(v) for v in s.model_figures.get("views_left_out") or []) or None),
            ("chamfer", _mm(acc.get("chamfer_mm"))), ("total time", _sec(s.report.get("seconds_total"))),
            ("simulated", "yes" if s.simulated else "no")]
    err = s.journal.get("error")
    if err:
        rows.append(("error", f"{err.get('code')}: {err.get('message')}"))
    return "<section><h2>Summary</h2>" + _kv_table(rows) + "</section>"


@dataclass
class ModelErrors:
    """The model aligned to ground truth and each point's distance to the true surface (computed once per page)."""

    aligned: np.ndarray  # (N, 3) model points in the ground truth's frame
    rgb: np.ndarray | None
    normals: np.ndarray | None
    err_mm: np.ndarray
    accuracy: dict[str, Any]


def _model_errors(s: SessionData, cfg: ReportConfig, rng: np.random.Generator) -> ModelErrors | None:
    """None when there is no model or no ground truth (not a simulated session)."""
    if s.model is None:
        return None
    gt = ground_truth_points(s, cfg.gt_points) if s.simulated else None
    if gt is None:
        return None
    from services.registration.api import chamfer_metrics, point_errors

    acc = dict(s.accuracy or {})
    T = np.asarray(acc.get("T_gt_model", np.eye(4)), dtype=np.float64).reshape(4, 4)
    xyz, rgb, nrm = _subsample(s.model, cfg.max_render_points, rng)
    aligned = xyz @ T[:3, :3].T + T[:3, 3]
    if "chamfer_mm" not in acc:
        acc.update(chamfer_metrics(aligned, gt))
        acc["aligned"] = False
    return ModelErrors(aligned, rgb, None if nrm is None else nrm @ T[:3, :3].T,
                       1000.0 * point_errors(aligned, gt), acc)


def _accuracy(s: SessionData, cfg: ReportConfig, errors: ModelErrors | None) -> str:
    head = "<section><h2>Accuracy against ground truth</h2>"
    if s.model is None:
        return head + "<p class='missing'>No model: nothing to measure.</p></section>"
    if errors is None:
        return head + "<p class='missing'>Ground truth unknown (not a simulated session).</p></section>"
    acc, err_mm, aligned = errors.accuracy, errors.err_mm, errors.aligned
    colors = colormap(err_mm, 0.0, cfg.error_vmax_mm)
    images = "".join(_figure(render_points(aligned, colors, cam, normals=errors.normals, radius_px=1),
                             f"azimuth {az:.0f}°, elevation {el:.0f}°")
                     for az, el, cam in _orbit(aligned, cfg.error_angles_deg, cfg))
    rows = [("chamfer", _mm(acc.get("chamfer_mm"))), ("accuracy (model → GT)", _mm(acc.get("accuracy_mm"))),
            ("completeness (GT → model)", _mm(acc.get("completeness_mm"))),
            ("F-score @ 2 mm", _pct(acc.get("fscore_2mm"))), ("F-score @ 5 mm", _pct(acc.get("fscore_5mm"))),
            ("per-point error: median / 95th pct / max",
             f"{np.median(err_mm):.2f} / {np.percentile(err_mm, 95):.2f} / {err_mm.max():.2f} mm"),
            ("aligned to GT before measuring", "yes" if acc.get("aligned", True) else "no")]
    return (head + _kv_table(rows) + "<p>Distance of every model point to the true surface:</p>" + _colorbar(cfg)
            + f"<div class='row'>{images}</div></section>")


def _colorbar(cfg: ReportConfig) -> str:
    return (f"<div class='colorbar'><span>0 mm</span><div class='grad'></div>"
            f"<span>≥ {cfg.error_vmax_mm:g} mm</span></div>")


def _model(s: SessionData, cfg: ReportConfig, rng: np.random.Generator, errors: ModelErrors | None) -> str:
    head = "<section><h2>Model</h2>"
    if s.model is None:
        return head + "<p class='missing'>No model.ply in the session (the run did not reach the model step).</p>" \
                      "</section>"
    xyz, rgb, nrm = _subsample(s.model, cfg.max_render_points, rng)
    images = "".join(_figure(render_points(xyz, rgb, cam, normals=nrm, radius_px=1),
                             f"azimuth {az:.0f}°, elevation {el:.0f}°")
                     for az, el, cam in _orbit(xyz, cfg.model_angles_deg, cfg))
    if errors is not None:  # in the ground truth's frame, coloured either way
        interactive = viewer_html(errors.aligned, errors.rgb, colormap(errors.err_mm, 0.0, cfg.error_vmax_mm),
                                  caption="drag to turn, wheel to zoom; error colours as above", seed=cfg.seed)
        note = _colorbar(cfg)
    else:
        interactive = viewer_html(xyz, rgb, caption="drag to turn, wheel to zoom", seed=cfg.seed)
        note = ""
    mesh = _mesh_viewer(s)
    if mesh:
        interactive = f"<div class='row'><div>{interactive}</div><div>{mesh}</div></div>"
    return (head + f"<p>{len(s.model)} points. Turn and zoom it here (up to {VIEWER_POINTS} points, drawn by"
            f" the page itself, offline){', beside the exported closed mesh' if mesh else ''}:</p>{note}"
            f"{interactive}<p>Rendered on the CPU:</p><div class='row'>{images}</div></section>")


def _mesh_viewer(s: SessionData) -> str:
    """The exported closed mesh (``SESSION/mesh.ply``, ``objscan export``) in the viewer; '' without one."""
    import open3d as o3d

    path = s.path / "mesh.ply"
    if not path.is_file():
        return ""
    mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        return ""
    if len(mesh.triangles) > MESH_TRIANGLES:
        mesh = mesh.simplify_quadric_decimation(MESH_TRIANGLES)
    tri = np.asarray(mesh.triangles)
    rgb = None
    if mesh.has_vertex_colors():
        rgb = np.clip(np.asarray(mesh.vertex_colors)[tri].mean(axis=1) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return mesh_viewer_html(np.asarray(mesh.vertices), tri, rgb,
                            caption=f"the exported mesh: {len(tri)} triangles, closed (objscan export)")


def _graph(s: SessionData) -> str:
    head = "<section><h2>Registration graph</h2>"
    edges = s.model_figures.get("edges") or []
    if not edges:
        return head + "<p class='missing'>No dynamic registration figures.</p></section>"
    n = max([len(s.views)] + [int(e.get("source_view", 0)) + 1 for e in edges]
            + [int(e.get("target_view", 0)) + 1 for e in edges])
    svg = registration_graph_svg(n, edges, s.model_figures.get("dropped_edge"))
    rows = "".join(
        f"<tr><td>{e.get('source_view')} → {e.get('target_view')}</td><td>{_num(e.get('fitness'), 3)}</td>"
        f"<td>{_num(e.get('rmse_mm'), 2)}</td><td>{_num(e.get('color_fitness'), 3)}</td>"
        f"<td>{html.escape(str(e.get('path', '')))}</td><td>{_num(e.get('seconds'), 2)}</td></tr>" for e in edges)
    loop = s.model_figures.get("loop_closure") or {}
    loop_txt = ", ".join(f"{k} {_num(v, 3)}" for k, v in loop.items() if isinstance(v, int | float))
    table = ("<table><thead><tr><th>edge</th><th>fitness</th><th>RMSE mm</th><th>color fitness</th><th>path</th>"
             f"<th>s</th></tr></thead><tbody>{rows}</tbody></table>")
    note = (f"<p>Configuration <b>{html.escape(str(s.model_figures.get('configuration')))}</b>"
            f" ({html.escape(str(s.model_figures.get('reason', '')))}); combine "
            f"{html.escape(str(s.model_figures.get('combine', '')))}; loop closure: {html.escape(loop_txt) or 'n/a'}."
            " Edge color and width follow fitness; a dashed edge was dropped.</p>")
    return head + note + f"<div class='row'><div>{svg}</div><div>{table}</div></div></section>"


def _views(s: SessionData, cfg: ReportConfig) -> str:
    cards = "".join(_view_card(v, s, cfg) for v in s.views)
    return f"<section><h2>Views</h2>{cards}</section>"


def _view_card(v: ViewData, s: SessionData, cfg: ReportConfig) -> str:
    thumbs = []
    frame0 = None
    for d in v.scan_dirs:
        try:
            thumbs.append(_figure(Image.open(d / "color.png").convert("RGB"), d.name, cfg.thumb_side))
        except OSError:
            thumbs.append(f"<p class='missing'>{d.name}: unreadable color.png</p>")
    if v.scan_dirs:
        try:
            frame0 = read_scan_dir(v.scan_dirs[0])
        except Exception:  # noqa: BLE001 - a broken scan must not sink the whole report
            frame0 = None
    chosen_mode, chosen_idx = _chosen(v, s)
    grasp = _grasp_record(v, chosen_mode, chosen_idx)
    if v.object_cloud is not None and frame0 is not None:
        img = _object_from_camera(v, frame0, grasp)
        drawn = grasp is not None and np.asarray(grasp.get("contacts", []), dtype=float).shape == (2, 3)
        thumbs.append(_figure(img, "object" + (" + chosen grasp" if drawn else "") + " (scan_0 camera)",
                              cfg.thumb_side))
    elif v.object_cloud is None:
        thumbs.append("<p class='missing'>No isolated object (view not registered).</p>")
    figures = v.figures or {}
    facts = [("commanded turn", f"{v.commanded_turn_deg:g}°"), ("scans", len(v.scan_dirs)),
             ("object points", None if v.object_cloud is None else len(v.object_cloud)),
             ("object height", _mm(1000.0 * figures["object_height_m"]) if "object_height_m" in figures else None),
             ("registration time", _sec((figures.get("timings_s") or {}).get("total")))]
    if v.chosen:
        facts.append(("turned with", f"grasp {v.chosen.get('grasp')} ({v.chosen.get('kind')}, pose "
                                     f"{v.chosen.get('pose')}, {chosen_mode} plan)"))
    return (f"<div class='card'><h3>View {v.index}</h3><div class='row'>{''.join(thumbs)}</div>"
            f"{_kv_table(facts)}{_grasp_tables(v, chosen_mode, chosen_idx)}</div>")


def _chosen(v: ViewData, s: SessionData) -> tuple[str | None, int | None]:
    """(plan mode, grasp index) of the grasp that turned the object after this view."""
    if v.chosen is None:
        return None, None
    mode = None
    for d in v.decisions:
        if d is v.chosen:
            break
        if d.get("what") == "grasps planned":
            mode = d.get("mode")
    if mode is None and len(v.grasp_plans) == 1:
        mode = next(iter(v.grasp_plans))
    idx = v.chosen.get("grasp")
    return mode, int(idx) if isinstance(idx, int) else None


def _grasp_record(v: ViewData, mode: str | None, idx: int | None) -> dict[str, Any] | None:
    if mode is None or idx is None:
        return None
    grasps = (v.grasp_plans.get(mode) or {}).get("grasps") or []
    return grasps[idx] if 0 <= idx < len(grasps) else None


def _grasp_tables(v: ViewData, chosen_mode: str | None, chosen_idx: int | None) -> str:
    if not v.grasp_plans:
        return ""
    out = []
    for mode, plan in v.grasp_plans.items():
        rows = []
        for i, g in enumerate(plan.get("grasps") or []):
            mark = " class='chosen'" if mode == chosen_mode and i == chosen_idx else ""
            rows.append(f"<tr{mark}><td>{i}</td><td>{html.escape(str(g.get('kind')))}</td>"
                        f"<td>{_num(g.get('rank'), 2)}</td><td>{_mm(1000.0 * g['width']) if 'width' in g else ''}"
                        f"</td></tr>")
        out.append(f"<p>Grasp plan <b>{html.escape(mode)}</b>: {html.escape(str(plan.get('explanation', '')))}</p>"
                   "<table><thead><tr><th>#</th><th>kind</th><th>rank</th><th>width</th></tr></thead>"
                   f"<tbody>{''.join(rows[:8])}</tbody></table>")
    return "".join(out)


def _object_from_camera(v: ViewData, frame, grasp: dict[str, Any] | None) -> Image.Image:  # noqa: ANN001
    intr = frame.intrinsics
    cam = RasterCamera(np.asarray(frame.T_base_camera, float), intr.fx, intr.fy, intr.cx, intr.cy, intr.width,
                 intr.height)
    cloud = v.object_cloud
    img = Image.fromarray(render_points(cloud.xyz, cloud.rgb, cam, normals=cloud.normals, radius_px=2,
                                        background=(235, 238, 242)))
    contacts = np.asarray(grasp.get("contacts", []), dtype=float) if grasp else np.zeros((0, 3))
    if contacts.shape == (2, 3):
        T_cw = np.linalg.inv(cam.T_world_camera)
        pc = contacts @ T_cw[:3, :3].T + T_cw[:3, 3]
        uv = np.column_stack([cam.fx * pc[:, 0] / pc[:, 2] + cam.cx, cam.fy * pc[:, 1] / pc[:, 2] + cam.cy])
        draw = ImageDraw.Draw(img)
        draw.line([tuple(uv[0]), tuple(uv[1])], fill=(220, 20, 60), width=4)
        for u, w in uv:
            draw.ellipse([u - 9, w - 9, u + 9, w + 9], outline=(220, 20, 60), width=4)
    return _crop_to(img, cam, np.asarray(cloud.xyz, float), margin=0.3)


def _crop_to(img: Image.Image, cam: RasterCamera, xyz: np.ndarray, margin: float) -> Image.Image:
    """Crop ``img`` to the projected bounds of ``xyz`` plus ``margin`` (the object is small in a full frame)."""
    T_cw = np.linalg.inv(cam.T_world_camera)
    pc = xyz @ T_cw[:3, :3].T + T_cw[:3, 3]
    pc = pc[pc[:, 2] > 1e-6]
    if pc.shape[0] == 0:
        return img
    u = cam.fx * pc[:, 0] / pc[:, 2] + cam.cx
    v = cam.fy * pc[:, 1] / pc[:, 2] + cam.cy
    cu, cv = (u.min() + u.max()) / 2, (v.min() + v.max()) / 2
    half = max(u.max() - u.min(), v.max() - v.min(), 60.0) * (0.5 + margin)
    box = (int(max(cu - half * 4 / 3, 0)), int(max(cv - half, 0)), int(min(cu + half * 4 / 3, img.width)),
           int(min(cv + half, img.height)))
    return img.crop(box) if box[2] > box[0] and box[3] > box[1] else img


def _timings(s: SessionData) -> str:
    return f"<section><h2>Timings per step</h2>{timings_svg(s.timings_s)}</section>"


def _decisions(s: SessionData) -> str:
    if not s.decisions:
        return "<section><h2>Decisions</h2><p class='missing'>No journal.</p></section>"
    rows = "".join(
        f"<tr><td>{_num(d.get('t'), 1)}</td><td>{d.get('view')}</td><td>{html.escape(str(d.get('state')))}</td>"
        f"<td>{html.escape(str(d.get('what')))}</td><td>{html.escape(_detail(d))}</td></tr>" for d in s.decisions)
    return (f"<section><h2>Decisions</h2><details><summary>{len(s.decisions)} decisions</summary><table><thead><tr>"
            f"<th>t (s)</th><th>view</th><th>state</th><th>what</th><th>detail</th></tr></thead><tbody>{rows}"
            "</tbody></table></details></section>")


# ------------------------------------------------------------------------------------------------ helpers
def _subsample(cloud, n: int, rng: np.random.Generator):  # noqa: ANN001, ANN202
    xyz = np.asarray(cloud.xyz, dtype=np.float64)
    idx = np.arange(xyz.shape[0]) if xyz.shape[0] <= n else np.sort(rng.choice(xyz.shape[0], n, replace=False))
    rgb = None if cloud.rgb is None else np.asarray(cloud.rgb)[idx]
    nrm = None if cloud.normals is None else np.asarray(cloud.normals, dtype=np.float64)[idx]
    return xyz[idx], rgb, nrm


def _orbit(xyz: np.ndarray, angles, cfg: ReportConfig):  # noqa: ANN001, ANN202
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    center = (lo + hi) / 2.0
    radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)
    w, h = cfg.render_size
    for az, el in angles:
        yield az, el, orbit_camera(center, radius, az, el, w, h, fill=0.95)


def _figure(image, caption: str, max_side: int | None = None) -> str:  # noqa: ANN001
    return (f"<figure><img src=\"{png_data_uri(image, max_side)}\" alt=\"{html.escape(caption)}\">"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _kv_table(rows: list[tuple[str, Any]]) -> str:
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape('—' if v is None else str(v))}</td></tr>"
                   for k, v in rows)
    return f"<table class='kv'>{body}</table>"


def _detail(d: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in d.items() if k not in ("t", "view", "state", "what"))[:300]


def _num(v: Any, digits: int) -> str:
    return f"{v:.{digits}f}" if isinstance(v, int | float) and np.isfinite(v) else "—"


def _mm(v: Any) -> str | None:
    return f"{v:.2f} mm" if isinstance(v, int | float) and np.isfinite(v) else None


def _sec(v: Any) -> str | None:
    return f"{v:.1f} s" if isinstance(v, int | float) and np.isfinite(v) else None


def _pct(v: Any) -> str | None:
    return f"{100.0 * v:.1f} %" if isinstance(v, int | float) and np.isfinite(v) else None


_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:24px;color:#222;background:#fafafa}
h1{margin:0 0 12px}h2{border-bottom:2px solid #1f4e79;padding-bottom:4px;margin-top:28px}
section{margin-bottom:16px}.row{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}
figure{margin:0;background:#fff;border:1px solid #ddd;padding:4px}figure img{display:block;max-width:100%}
figcaption{font-size:12px;color:#555;text-align:center}
table{border-collapse:collapse;font-size:13px;margin:6px 0}td,th{border:1px solid #ddd;padding:3px 8px;text-align:left}
table.kv th{background:#eef3f8;font-weight:600}tr.chosen{background:#d9f2d9;font-weight:600}
.card{background:#fff;border:1px solid #ccd;border-radius:6px;padding:10px 14px;margin:12px 0}
.card h3{margin:0 0 8px}.missing{color:#a33;font-style:italic}
.colorbar{display:flex;align-items:center;gap:8px;font-size:12px}
.colorbar .grad{width:260px;height:14px;background:linear-gradient(to right,#440154,#472c7a,#3b518b,#2c718e,
#21908d,#27ad81,#5cc863,#aadc32,#fde725)}
footer{margin-top:30px;font-size:12px;color:#777}
"""
