"""Session recording (MCAP: raw msgpack payloads + Foxglove visual channels) and replay.

- ``recorder.SessionRecorder``: what the orchestrator writes while it runs;
- ``reader.read_recording`` / ``reader.recover``: reading it back, crashed files included;
- ``replay_cell``: camera and arm services that answer from a recording (full replay);
- ``replay.replay_session``: the full replay; ``registration.replay_registration``: registration only;
- ``compare.compare_models``: the determinism check.
"""
