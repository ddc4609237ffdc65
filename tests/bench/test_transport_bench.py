"""``objscan bench transport`` runs end to end on a few samples: both topologies (through the router, and two
processes linked peer to peer, the documented ``OBJSCAN_ZENOH_MODE=peer``) serve the frame, and the JSON keys
the issue names are there. Speed itself is the benchmark's business, not this test's."""

from __future__ import annotations

import pytest

from bench.transport import codec_figures, roundtrip_figures

pytestmark = pytest.mark.timeout(180)


def test_transport_bench_measures_both_links_and_the_codec():
    figures = roundtrip_figures(5)
    assert figures["roundtrip_samples"] == 5
    for key in ("roundtrip_ms_median", "roundtrip_direct_ms_median"):
        assert 0 < figures[key] < 10_000, figures
    codec = codec_figures(5)
    assert codec["frame_bytes"] > 848 * 480 * 5  # colour + depth travel whole
    assert codec["codec_vs_copy_ratio"] > 0
