"""Static scan registration and goal-object isolation (paper section II-A).

The registration service face and ``objscan reconstruct`` call :func:`register_view`.
"""

from .config import StaticConfig
from .errors import (
    BadFramesError,
    EmptyDepthError,
    NoObjectError,
    NoTableError,
    RegistrationFailedError,
    StaticRegistrationError,
)
from .pipeline import register_view
from .result import ScanResult, StaticViewResult

__all__ = [
    "BadFramesError",
    "EmptyDepthError",
    "NoObjectError",
    "NoTableError",
    "RegistrationFailedError",
    "ScanResult",
    "StaticConfig",
    "StaticRegistrationError",
    "StaticViewResult",
    "register_view",
]
