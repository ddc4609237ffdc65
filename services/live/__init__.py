"""The live view: a scan as it happens (or a recorded one) in Rerun and over the Foxglove WebSocket.

One interpreter (``scene``) turns the messages a scan already exchanges into events; sinks draw them
(``rerun_sink``, ``foxglove_sink``); ``feed`` follows a cell over Zenoh or replays a recording; ``tap``
is the orchestrator's side (it publishes each exchange of a run started with ``live: true``).
See docs/live-view.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the CLI imports this package for its flags; the heavy parts load only when used
    from services.live.feed import LiveView

__all__ = ["add_live_args", "live_requested", "open_live_view", "replay_recording"]


def add_live_args(p: argparse.ArgumentParser) -> None:
    """``--rerun``, ``--rerun-save FILE.rrd``, ``--foxglove`` and ``--foxglove-port`` on a command."""
    g = p.add_argument_group("live view")
    g.add_argument("--rerun", action="store_true", help="stream to a Rerun viewer (spawns the one in rerun-sdk)")
    g.add_argument("--rerun-save", metavar="FILE.rrd", help="stream into a Rerun recording file")
    g.add_argument("--foxglove", action="store_true",
                   help="serve the scan over the Foxglove WebSocket (connect Foxglove to ws://127.0.0.1:PORT)")
    g.add_argument("--foxglove-port", type=int, default=8765, help="Foxglove WebSocket port (default: %(default)s)")


def live_requested(args: argparse.Namespace) -> bool:
    return bool(args.rerun or args.rerun_save or args.foxglove)


def open_live_view(args: argparse.Namespace) -> LiveView:
    """The sinks the flags ask for (imports rerun/foxglove only when asked)."""
    from services.live.feed import LiveView

    sinks: list[Any] = []
    if args.rerun or args.rerun_save:
        from services.live.rerun_sink import RerunSink

        sinks.append(RerunSink(save=Path(args.rerun_save) if args.rerun_save else None, spawn=args.rerun))
    if args.foxglove:
        from services.live.foxglove_sink import FoxgloveSink

        sinks.append(FoxgloveSink(port=args.foxglove_port))
    return LiveView(sinks)


def replay_recording(source: str | Path, view: LiveView, *, speed: float | None = None) -> dict[str, int]:
    """``services.live.feed.replay_recording``: a recorded session into ``view``."""
    from services.live.feed import replay_recording as replay

    return replay(source, view, speed=speed)
