"""``objscan replay``: run a recorded session again and check the model comes out the same.

- ``objscan replay SESSION_DIR_OR_MCAP --out DIR``: the full replay (``services/recording/replay.py``):
  registration, grasp and orchestrator live, camera and arm answering from the recording, no sim;
  a new session folder in DIR with ``DIR/model.ply``.
- ``objscan replay SESSION_DIR_OR_MCAP --out DIR --only registration``: just the registration (static per
  view, then dynamic) on the recorded frames, in-process (``services/recording/registration.py``);
  ``--static-profile`` / ``--dynamic-config`` try another method on the same scans.

- ``objscan replay SESSION_DIR_OR_MCAP --rerun-save FILE.rrd`` (or ``--rerun``, ``--foxglove``) without
  ``--out``: no re-run; the recorded exchanges and streams go into the live view (``services/live``),
  exactly as they were seen during the scan.

Both re-runs print the comparison with the recorded model and exit 0 when the replay finished and its model is
identical or within ``--tolerance-mm``; 1 when it differs or the replay itself failed (one line on stderr with
its code); 2 when the recording does not exist or the arguments are wrong. Details in ``DIR/replay.json``;
docs/recording.md explains what is compared.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from common.errors import ObjscanError
from services.cli.outcome import BadUsage, print_json, require_path
from services.live import add_live_args, live_requested, open_live_view, replay_recording


def register(sub) -> None:  # noqa: ANN001 - argparse sub-parsers
    p = sub.add_parser("replay", help="replay a recorded session (full, or registration only) and compare models",
                       description="Replay a recorded session against the services, or re-run only its "
                                   "registration, writing a new session folder with its model.")
    add_arguments(p)
    p.set_defaults(func=run)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SESSION_DIR_OR_MCAP", help="a recorded session folder or its session.mcap")
    p.add_argument("--out", help="new session folder for the replay (needed unless only viewing with a live-view flag)")
    p.add_argument("--only", choices=["registration"], help="re-run only this stage, in-process")
    p.add_argument("--static-profile", help="registration only: static profile (default: the recorded one)")
    p.add_argument("--dynamic-config", help="registration only: dynamic config as JSON (default: the recorded one)")
    p.add_argument("--tolerance-mm", type=float, default=0.5,
                   help="largest model difference (Hausdorff, mm) still counted as the same (default: %(default)s)")
    p.add_argument("--atol", type=float, default=1e-4,
                   help="full replay: largest difference between a live and a recorded camera/arm request "
                        "(m, rad) (default: %(default)s)")
    p.add_argument("--timeout", type=float, default=1800.0, help="full replay: give up after this many seconds")
    add_live_args(p)
    p.add_argument("--speed", type=float, default=5.0,
                   help="--foxglove view: replay at this multiple of the recorded time (default: %(default)s)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="no progress; print one JSON object at the end (model, comparison, same; or the error)")


def _print_comparison(report: dict[str, Any], as_json: bool) -> int:
    """The comparison with the recorded model: 0 the same (or within tolerance), 1 it differs or none was built."""
    cmp_ = report.get("comparison")
    code = 0 if (cmp_ and (cmp_["identical"] or cmp_["within_tolerance"]
                           or (cmp_.get("xyz_identical") and cmp_.get("rgb_identical")))) \
        or (not cmp_ and report.get("model")) else 1
    if as_json:
        print_json({"model": report.get("model"), "comparison": cmp_, "same": code == 0})
        return code
    if not cmp_:
        if report.get("model"):
            print("no recorded model to compare with")
            return 0
        raise ObjscanError("the replay produced no model", code="no_model")
    if cmp_["identical"]:
        print(f"model identical to the recording ({cmp_['points_replayed']} points, byte for byte)")
    elif cmp_.get("xyz_identical") and cmp_.get("rgb_identical"):
        print(f"model points and colours identical to the recording ({cmp_['points_replayed']} points, byte for "
              f"byte); normals differ by at most {cmp_.get('normals_max_diff', 0.0):.2g}")
    else:
        print(f"model differs from the recording: chamfer {cmp_['chamfer_mm']} mm, hausdorff {cmp_['hausdorff_mm']} "
              f"mm, points {cmp_['points_recorded']} -> {cmp_['points_replayed']} "
              f"({'within' if cmp_['within_tolerance'] else 'beyond'} {cmp_['tolerance_mm']} mm)")
    return code


def _view(args: argparse.Namespace) -> int:
    """The recording into the live-view sinks, no re-run (Foxglove: serve until Ctrl-C)."""
    view = open_live_view(args)
    try:
        if args.foxglove:  # a WebSocket client sees only what is sent while it is connected: play it in a loop
            print(f"Foxglove: connect to ws://127.0.0.1:{args.foxglove_port}; replaying at {args.speed}x "
                  "in a loop (Ctrl-C to stop)")
            while True:
                replay_recording(args.source, view, speed=args.speed)
                view.reset()  # the next loop starts from a fresh scene
        counts = replay_recording(args.source, view)
        print("replayed into the live view: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    finally:
        view.close()
    return 0


def run(args: argparse.Namespace) -> int:
    require_path(args.source, "recording")
    if args.out is None:
        if not live_requested(args):
            raise BadUsage("give --out DIR (re-run the session) or a live-view flag (--rerun, --rerun-save, "
                           "--foxglove) to watch it")
        return _view(args)
    say = (lambda *a, **k: None) if args.json_output else print
    if args.only == "registration":
        from services.recording.registration import replay_registration

        try:
            dyn = json.loads(args.dynamic_config) if args.dynamic_config else None
        except ValueError as exc:
            raise BadUsage(f"--dynamic-config is not JSON: {exc}") from None
        report = replay_registration(args.source, args.out, static_profile=args.static_profile,
                                     dynamic_config=dyn, tolerance_mm=args.tolerance_mm, progress=say)
    else:
        from services.recording.replay import replay_session

        def show(status: dict[str, Any]) -> None:
            say(f"\rview {status.get('view')}: {status.get('state'):<12} "
                f"({status.get('views_done', 0)}/{status.get('views')} views)", end="", flush=True)

        report = replay_session(args.source, args.out, atol=args.atol, tolerance_mm=args.tolerance_mm,
                                timeout_s=args.timeout, progress=show)
        say()
        status = report.get("status", {})
        if status.get("status") != "done":
            err = status.get("last_error") or {}
            div = (report.get("arm") or {}).get("diverged") or (report.get("camera") or {}).get("diverged")
            raise ObjscanError(f"replay {status.get('status')}: {err.get('message', 'it did not finish')}"
                               + (f"; diverged from the recording: {json.dumps(div)}" if div else "")
                               + f"; details: {args.out}/replay.json",
                               code=str(err.get("code") or "replay_failed"), detail={"replay": str(args.out)})
    say(f"model: {report.get('model')}")
    return _print_comparison(report, args.json_output)


def main(argv: list[str] | None = None) -> int:
    from services.cli.main import main as objscan

    return objscan(["replay", *(argv if argv is not None else sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
