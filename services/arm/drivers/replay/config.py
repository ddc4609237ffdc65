"""Configuration of the replay driver."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from common.backend_options import option
from services.arm.errors import BadCommand


@dataclass(frozen=True)
class ReplayDriverOptions:
    """``--option session=DIR`` on the arm service."""

    session: str = option("", "the session folder whose recorded joints to report")


@dataclass
class ReplayDriverConfig:
    """The session folder whose recorded joints (each scan's ``meta.json``) the driver reports."""

    session: Path

    def __post_init__(self) -> None:
        if not self.session:
            raise BadCommand("the replay backend needs a session folder (--option session=DIR)", code="bad_value")
        self.session = Path(self.session)
