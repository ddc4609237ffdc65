"""Typed errors of the ROS 2 face and the bag writer."""

from __future__ import annotations

from common.errors import ObjscanError


class BagError(ObjscanError):
    """A ROS 2 bag cannot be written (an existing output folder: a bag is never written over)."""

    code = "bag_failed"
