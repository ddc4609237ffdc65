"""Configuration of the sim driver."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SimDriverConfig:
    """Where the twin's arm starts. ``initial_q`` is a camera-up home pose clear of the table."""

    initial_q: tuple[float, ...] = (0.0, -0.3, -0.9, 0.0, 1.2, 0.0)
    initial_opening: float = 0.106
