"""Typed errors of the model library; every one carries a stable ``code`` a caller can branch on."""

from __future__ import annotations

from common.errors import ObjscanError


class LibraryError(ObjscanError):
    """The library folder or its index cannot be used (unreadable, not a library, I/O failure)."""

    code = "library_error"


class ModelNotFound(LibraryError):
    """No stored model has the id (or id prefix) asked for; ``detail`` says which, and any ambiguity."""

    code = "model_not_found"


class BadModelInput(LibraryError):
    """What was given to store or match is unusable: empty or NaN cloud, wrong shape, bad metadata."""

    code = "bad_model"


class UnacceptedModel(LibraryError):
    """The model was built but not accepted by the dynamic stage's own checks (``accepted: false``): the
    library keeps only models it can match against, unless the caller takes it explicitly
    (``allow_unaccepted=True``)."""

    code = "model_not_accepted"
