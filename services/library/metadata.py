"""What the library records about a model, next to its files (``metadata.json``) and in the index.

A plain dataclass rather than a free dict so every writer fills the same fields; ``extra`` keeps anything
else a caller wants to remember (readers ignore keys they do not know, as for session folders).
"""

from __future__ import annotations

import re
import time
from dataclasses import asdict, dataclass, field
from typing import Any

from services.library.errors import BadModelInput

METADATA_VERSION = 1


@dataclass
class ModelMetadata:
    """Facts about one stored model.

    - ``object_name``: what the model is of (e.g. ``milk``); the library's search key for people.
    - ``created``: UNIX time the model was built (defaults to now).
    - ``session``: the acquisition folder it came from, when any.
    - ``configuration``: the dynamic-registration configuration chosen (``no_region``, ``region_crop``, ...).
    - ``quality``: figures to judge it (points, loop closure, accuracy against ground truth when known...).
    - ``descriptor``: GOOD of the whole model (filled by the library on ``add``; see ``descriptors``).
    """

    object_name: str
    created: float = field(default_factory=time.time)
    session: str | None = None
    configuration: str | None = None
    quality: dict[str, Any] = field(default_factory=dict)
    source: str = "user"
    extra: dict[str, Any] = field(default_factory=dict)
    descriptor: dict[str, Any] = field(default_factory=dict)

    def validate(self) -> None:
        if not isinstance(self.object_name, str) or not self.object_name.strip():
            raise BadModelInput("metadata.object_name must be a non-empty string",
                                detail={"field": "object_name"})
        if not isinstance(self.created, int | float) or self.created != self.created:
            raise BadModelInput("metadata.created must be a UNIX time", detail={"field": "created"})
        for name in ("quality", "extra", "descriptor"):
            if not isinstance(getattr(self, name), dict):
                raise BadModelInput(f"metadata.{name} must be a dict", detail={"field": name})

    def to_dict(self) -> dict[str, Any]:
        return {"version": METADATA_VERSION, **asdict(self)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelMetadata:
        """Build from a dict (unknown keys go to ``extra`` so nothing a newer writer added is lost)."""
        if not isinstance(data, dict):
            raise BadModelInput("metadata must be a mapping", detail={"type": type(data).__name__})
        known = {"object_name", "created", "session", "configuration", "quality", "source", "extra", "descriptor"}
        kwargs = {k: v for k, v in data.items() if k in known}
        if "object_name" not in kwargs:
            if "object" in data:  # the session-folder spelling
                kwargs["object_name"] = data["object"]
            else:
                raise BadModelInput("metadata lacks object_name", detail={"field": "object_name"})
        extra = dict(kwargs.pop("extra", {}) or {})
        extra.update({k: v for k, v in data.items() if k not in known and k not in ("version", "object")})
        meta = cls(**kwargs, extra=extra)
        meta.validate()
        return meta


def slug(text: str) -> str:
    """File-name-safe lower-case form of an object name (``Orange Juice!`` -> ``orange-juice``)."""
    s = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")
    return s[:40] or "model"
