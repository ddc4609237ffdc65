"""The demo objects that ship with objscan, by name: ``carton``, ``can``, ``flat_box``.

The twin needs an object to scan, and the HOPE meshes it was developed on are licensed for non-commercial
use only, so they cannot ship with the project. These objects are made by code in this repository
(``demo_meshes.py``) and committed as generated files under ``services/sim/objects/<name>/`` in the HOPE
folder layout (``textured.obj``, ``textured.mtl``, ``texture_map.png``), so every checkout and the image hold
them and ``catalogue.load_object("carton")`` reads them through the same OBJ path as any user mesh. The files
are in metres with z up and the origin at the bottom centre of the footprint, so a mesh file's defaults
(``scale=1``, ``up_axis="z"``) apply, by name or by path.

``python -m services.sim.demo_objects`` writes them again after a change to the generator; ``--check``
compares instead (a test does the same). This module stays light (no OpenCV) because the CLI imports it.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from services.sim.demo_files import OBJECTS_DIR

#: The object the twin starts with and the demo scans: present in every checkout.
DEFAULT_OBJECT = "can"


@dataclass(frozen=True)
class DemoObject:
    """One demo object: its name and what it imitates (for listings and docs)."""

    name: str
    description: str


DEMO_OBJECTS: dict[str, DemoObject] = {
    o.name: o for o in (
        DemoObject("carton", "1 l milk carton with a gable top, 7 x 7 x 19.5 cm"),
        DemoObject("can", "400 g food can with a wrap-around label, 7.3 cm across, 11 cm tall"),
        DemoObject("flat_box", "box of crackers lying flat, 13 x 7.5 x 4.5 cm"),
    )
}


def demo_names() -> list[str]:
    """Names of the demo objects, in the order they are listed to users."""
    return list(DEMO_OBJECTS)


def demo_folder(name: str) -> Path | None:
    """The folder holding a demo object's files, or None when ``name`` is not a demo object."""
    return OBJECTS_DIR / name if name in DEMO_OBJECTS else None


def generate(name: str) -> dict[str, bytes]:
    """The files of demo object ``name`` (file name -> content), exactly as committed."""
    if name not in DEMO_OBJECTS:
        raise KeyError(f"not a demo object: {name!r} (demo objects: {', '.join(DEMO_OBJECTS)})")
    from services.sim.demo_meshes import BUILDERS

    return BUILDERS[name]().files()


def write(name: str, folder: Path) -> list[Path]:
    """Write demo object ``name`` into ``folder`` (created); the written paths."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for file_name, data in generate(name).items():
        path = folder / file_name
        path.write_bytes(data)
        out.append(path)
    return out


def differences(root: Path = OBJECTS_DIR) -> list[str]:
    """Files under ``root`` that differ from (or are missing against) what the generator makes now."""
    bad = []
    for name in DEMO_OBJECTS:
        for file_name, data in generate(name).items():
            path = root / name / file_name
            if not path.is_file() or path.read_bytes() != data:
                bad.append(str(path))
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m services.sim.demo_objects",
                                description="Write (or check) the demo objects' mesh, material and texture files.")
    p.add_argument("--out", type=Path, default=OBJECTS_DIR,
                   help="folder to write one sub-folder per object into (default: the package's objects folder)")
    p.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 when the files under --out differ from what the generator makes")
    args = p.parse_args(argv)
    if args.check:
        bad = differences(args.out)
        for path in bad:
            print(f"differs from the generator: {path}", file=sys.stderr)
        return 1 if bad else 0
    for name in DEMO_OBJECTS:
        for path in write(name, args.out / name):
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
