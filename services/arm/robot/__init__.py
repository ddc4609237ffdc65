"""The PAPRAS 6-DOF robot description objscan ships (URDF + collision meshes), see NOTICE.md."""

from pathlib import Path

ROBOT_DIR = Path(__file__).resolve().parent
URDF_PATH = ROBOT_DIR / "papras_6dof.urdf"
MESH_PACKAGE_DIR = ROBOT_DIR  # mesh paths in the URDF are relative to this folder

JOINT_NAMES = tuple(f"robot1/joint{i}" for i in range(1, 7))
"""The arm's six joints as the URDF names them, base to wrist: every joint state, robot file and driver uses them."""
