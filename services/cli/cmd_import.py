"""``objscan import SOURCE --out SESSION``: a fixed-camera RGB-D sequence into a session folder.

SOURCE is a folder of color + depth images (paired by the number in their names, in that order) or a
RealSense ``.bag``/``.db3`` recording. The camera stays put and the object turns (by hand, on a
turntable); ``base`` is made from the table plane, the turns are given (``--turn-step``) or estimated,
and the direction may be unknown (both are tried). Then ``objscan reconstruct SESSION --out MODEL``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rich.markup import escape

from services.cli.cmd_scan import console
from services.cli.outcome import BadUsage, print_json, require_path


def _turn_step(text: str) -> float | None:
    """``--turn-step``: a number of degrees, or ``none`` (estimate each turn)."""
    return None if text.strip().lower() == "none" else float(text)


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("import", help="turn a fixed-camera RGB-D sequence into a session folder",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("source", help="folder of RGB-D images, or a RealSense .bag/.db3 recording")
    p.add_argument("--out", required=True, help="session folder to write: absent or empty (refused otherwise)")
    p.add_argument("--intrinsics", help="color intrinsics 'fx,fy,cx,cy' (pixels) or a JSON file; "
                                        "required for a folder without intrinsics.json")
    p.add_argument("--depth-scale", type=float, default=0.001, help="metres per depth unit (default 0.001)")
    p.add_argument("--turn-step", type=_turn_step, default=None,
                   help="degrees the object turns between frames (a turntable's step); 'none' or omitted: "
                        "estimate every turn")
    p.add_argument("--turn-step-uncertainty", type=float, default=None,
                   help="the given step's uncertainty in degrees (default 2): a pair estimate further off the step "
                        "does not move a turn, and the model's turns are judged against it")
    p.add_argument("--direction", choices=["ccw", "cw", "unknown"], default="unknown",
                   help="turn direction seen from above (default: unknown, both are tried)")
    p.add_argument("--every", type=int, default=1,
                   help="keep one frame in N, applied while reading: skipped frames are never held (default 1)")
    p.add_argument("--max-frames", type=int, default=None,
                   help="refuse a sequence that keeps more frames than this (default 360; use --every)")
    p.add_argument("--object", default="imported", help="object name written to session.json")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="no progress lines; print one JSON object at the end (session, views, turns, or the error)")
    p.add_argument("--camera-up", default=None,
                   help="the world's up in the camera's optical frame 'x,y,z' (default 0,-1,0: an upright camera)")
    p.add_argument("--no-focal-calibration", action="store_true",
                   help="keep the given fx, fy even when a full-turn sequence's loop says they are off "
                        "(default: self-calibrate them, docs/importing.md)")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    require_path(args.source, "source")  # before the heavy imports: a missing source is said at once
    from services.importer.base_frame import BaseFrameConfig
    from services.importer.session import ImportConfig, import_sequence
    from services.importer.sources import parse_intrinsics

    console.quiet = bool(args.json_output)  # stdout is the JSON document only
    try:
        intr = parse_intrinsics(args.intrinsics) if args.intrinsics else None
        base = BaseFrameConfig() if args.camera_up is None else BaseFrameConfig(
            camera_up=tuple(float(v) for v in args.camera_up.split(",")))
        cfg = ImportConfig(turn_step_deg=args.turn_step, direction=args.direction, every=args.every,
                           depth_scale=args.depth_scale, object_name=args.object, base=base,
                           turn_step_sigma_deg=args.turn_step_uncertainty)
        if args.max_frames is not None:
            cfg = replace(cfg, max_frames=args.max_frames)
        if args.no_focal_calibration:
            cfg = replace(cfg, focal=replace(cfg.focal, enabled=False))
    except ValueError as exc:  # a number that is not one, a vector of the wrong length: bad usage
        raise BadUsage(str(exc)) from None

    def progress(info: dict) -> None:
        console.print(" ".join(f"{k}={v}" for k, v in info.items()))

    report = import_sequence(args.source, Path(args.out), intr, cfg, progress=progress)
    t = report["turns"]
    fc = report["focal_calibration"]
    if args.json_output:
        print_json({"session": str(args.out), "views": report["views"], "frames": report["frames"],
                    "turns": t, "base_frame": report["base_frame"], "focal_calibration": fc,
                    "seconds": report["seconds"]})
        return 0
    console.print(f"session: {args.out}; {report['views']} views of {report['frames']} frames; turns {t['source']}, "
                  f"direction {t['direction']} ({t['direction_source']}); camera "
                  f"{report['base_frame']['camera_height_m'] * 100:.1f} cm above the table; {report['seconds']:.1f} s")
    loop = t.get("loop", {})
    if report.get("skipped_count"):
        console.print(f"skipped: {report['skipped_count']} frames (one warning line each above)")
    console.print(f"turns: {t['status']}; loop {'closes' if loop.get('loop_closes') else 'open'}, total turn "
                  f"{loop.get('total_turn_deg')} deg" + (f"; {len(loop['unsure_pairs'])} unsure pairs"
                                                         if loop.get("unsure_pairs") else ""))
    for why in loop.get("reasons", []):
        console.print(f"[yellow]unsure:[/yellow] {escape(why)}")
    console.print(f"focal length: {'x ' + format(fc['scale'], '.4f') if fc['applied'] else 'kept'} "
                  f"(fx {fc['fx_before']} -> {fc['fx_after']}): {fc['reason']}")
    return 0
