"""Export: a finished acquisition as a closed, textured mesh in the object's own frame and a simulation asset.

``export_session(session, out)`` (``pipeline.py``) writes OBJ+MTL+PNG, GLB, PLY, STL, MJCF and URDF; the
modules are the steps (object frame, surface, cap, texture, collision parts, physics, writers) as plain
functions. docs/export.md says what each file holds and how to load it.
"""

from services.export.errors import ExportError, ExportInputError
from services.export.pipeline import DEFAULT_METHOD, export_session
from services.export.surface import METHODS
from services.export.writers import FORMATS

__all__ = ["DEFAULT_METHOD", "FORMATS", "METHODS", "ExportError", "ExportInputError", "export_session"]
