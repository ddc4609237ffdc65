"""Configuration of the sim driver."""

from __future__ import annotations

from dataclasses import dataclass

from services.arm.drivers.base import HOME_Q


@dataclass(frozen=True)
class SimDriverOptions:
    """The sim backend takes no ``--option``: the twin it drives is found over Zenoh."""


@dataclass
class SimDriverConfig:
    """Where the twin's arm starts. ``initial_q`` is a camera-up home pose clear of the table."""

    initial_q: tuple[float, ...] = HOME_Q
    initial_opening: float = 0.106
