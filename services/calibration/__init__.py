"""Calibration of the real cell: the ChArUco board (shared with the twin) and the hand-eye procedure."""
