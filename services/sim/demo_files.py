"""Where the demo objects' files are kept and what they are called: one folder per object, like the HOPE data.

Its own module so that the light side (``demo_objects``: names, folders) and the generator (``demo_meshes``:
OpenCV, numpy) both take the names from one place without importing each other.
"""

from __future__ import annotations

from pathlib import Path

OBJECTS_DIR = Path(__file__).resolve().parent / "objects"
MESH_FILE = "textured.obj"
MTL_FILE = "textured.mtl"
TEXTURE_FILE = "texture_map.png"
