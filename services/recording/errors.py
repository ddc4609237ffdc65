"""Typed errors of session recording and replay."""

from __future__ import annotations

from common.errors import ObjscanError


class RecordingError(ObjscanError):
    """A recording cannot be written or read (missing file, not an MCAP, no usable message)."""

    code = "bad_recording"


class ReplayDiverged(ObjscanError):
    """A replayed request differs from the recorded one beyond tolerance: the replay no longer follows
    the recording, so the recorded reply would be a lie."""

    code = "replay_diverged"


class ReplayExhausted(ObjscanError):
    """The replay was asked for more of a key than the recording holds."""

    code = "end_of_replay"
