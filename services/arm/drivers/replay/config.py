"""Configuration of the replay driver."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from services.arm.errors import BadCommand


@dataclass
class ReplayDriverConfig:
    """The session folder whose recorded joints (each scan's ``meta.json``) the driver reports."""

    session: Path

    def __post_init__(self) -> None:
        if not self.session:
            raise BadCommand("the replay backend needs a session folder (--session)", code="bad_value")
        self.session = Path(self.session)
