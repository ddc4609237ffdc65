"""``objscan export SESSION --out DIR``: a finished session as a closed, textured mesh and a simulation asset.

Writes, in the object's own frame (origin at the footprint centre on the table, z up, x along the long
side; metres): ``NAME.obj`` + ``.mtl`` + ``.png``, ``NAME.glb``, ``NAME.ply``, ``NAME.stl``, ``NAME.xml``
(MJCF) and ``NAME.urdf`` with their convex parts under ``collision/``, and ``export.json`` (the figures;
in simulation also the Chamfer distances of mesh and point model against the true mesh). docs/export.md.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from common.atomic import atomic_write_bytes
from common.errors import ObjscanError
from services.cli.cmd_ros2_bag import add_ros2_bag_options, write_ros2_bag
from services.cli.cmd_scan import console
from services.cli.library_attach import store_with_library_entry
from services.cli.outcome import OK, BadUsage, one_line, report_error


def register(sub) -> None:  # noqa: ANN001
    from services.export import DEFAULT_METHOD, FORMATS, METHODS

    p = sub.add_parser("export", help="turn a session's model into a watertight textured mesh and a sim asset",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("session", help="a finished session folder (with model.ply)")
    p.add_argument("--out", help="output folder of the mesh and asset files (created); required unless only a "
                                 "ROS 2 bag is asked for")
    p.add_argument("--format", default=",".join(FORMATS),
                   help=f"comma-separated formats out of {','.join(FORMATS)} (default: all)")
    mass = p.add_mutually_exclusive_group()
    mass.add_argument("--density", type=float, metavar="KG_M3",
                      help="density of the solid object, kg/m^3 (default: 1000, water)")
    mass.add_argument("--mass", type=float, metavar="KG", help="mass of the object, kg (sets the density)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=list(METHODS),
                   help="surface: Poisson on the point model, or TSDF fusion of the frames (default: %(default)s)")
    p.add_argument("--no-texture", action="store_true", help="vertex colours only, no baked texture image")
    p.add_argument("--no-evaluate", action="store_true",
                   help="skip the ground-truth figures of a simulated session")
    p.add_argument("--json", dest="json_file", metavar="F",
                   help="write the figures as one JSON object to file F ('-': stdout)")
    add_ros2_bag_options(p, required=False, flag="--ros2-bag", json_flag=False)
    p.set_defaults(func=run)


def parse_formats(text: str) -> tuple[str, ...]:
    """The ``--format`` list, checked against the known formats."""
    from services.export import FORMATS, ExportInputError

    wanted = tuple(dict.fromkeys(f.strip().lower() for f in text.split(",") if f.strip()))
    unknown = [f for f in wanted if f not in FORMATS]
    if not wanted or unknown:
        raise ExportInputError(f"--format takes a comma-separated list of {','.join(FORMATS)}; got {text!r}",
                               code="bad_argument", detail={"unknown": unknown})
    return wanted


def run(args) -> int:  # noqa: ANN001
    """Exit 0 with the files written, 1 (with one line on stderr) when the session cannot be exported."""
    from services.export import export_session

    to_stdout = args.json_file == "-"
    console.quiet = to_stdout
    if args.out is None and not args.ros2_bag:
        raise BadUsage("export needs --out DIR (the mesh and asset files) or --ros2-bag OUT (a ROS 2 bag)")
    if args.ros2_bag:  # the session's recording as a ROS 2 bag (docs/ros2.md)
        args.json = to_stdout
        code = write_ros2_bag(args.session, args)
        if code or args.out is None:
            return code
    try:
        formats = parse_formats(args.format)
        result = export_session(Path(args.session), Path(args.out), formats=formats, density=args.density,
                                mass=args.mass, method=args.method, texture=not args.no_texture,
                                evaluate=not args.no_evaluate)
    except ObjscanError as exc:
        code = report_error("export", exc, as_json=to_stdout)
        if args.json_file and not to_stdout:
            from services.cli.outcome import error_payload

            _write_json(Path(args.json_file), {"error": error_payload(exc)})
        return code
    entry = store_with_library_entry(Path(args.session), "export")
    if entry:
        result["library_entry"] = entry
    if args.json_file:
        if to_stdout:
            print(json.dumps(result, default=str))
        else:
            _write_json(Path(args.json_file), result)
    _say(result)
    return OK


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, (json.dumps(doc, indent=2, default=str) + "\n").encode())


def _say(r: dict[str, Any]) -> None:
    inertia = r["inertial"]
    console.print(f"exported {r['name']} to {r['out']} in {r['seconds']:.1f} s: {r['triangles']} triangles, "
                  f"watertight {r['watertight']}, {'textured' if r['textured'] else 'vertex colours'}, "
                  f"{r['parts']} convex part(s), mass {inertia['mass_kg']:.3f} kg")
    if "mesh_chamfer_mm" in r:
        console.print(one_line(f"against ground truth: mesh Chamfer {r['mesh_chamfer_mm']:.3f} mm, point model "
                               f"{r['points_chamfer_mm']:.3f} mm, volume ratio {r['volume_ratio']:.3f}"))
    for fmt, files in r["files"].items():
        console.print(f"  {fmt}: {', '.join(files)}")
    sys.stdout.flush()
