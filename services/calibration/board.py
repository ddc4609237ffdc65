"""The ChArUco calibration board: one definition shared by the twin (which renders it) and the hand-eye
procedure (which detects it), so the two can never disagree about squares, markers or sizes.

Board frame (OpenCV's): origin at the board's top-left corner as printed, x along the rows, y down the
columns, z into the board. ``T_object_board`` places it on the twin's board object (a thin plate standing
on the table, bottom centre at the origin, z up): looked at from above, the print reads upright.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from common.errors import ObjscanError


class BoardError(ObjscanError):
    """A board definition or a detection that cannot be used."""

    code = "bad_board"


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board: ``squares_x`` x ``squares_y`` chessboard squares, ArUco markers in the white ones.

    Defaults: 5 x 7 squares of 30 mm with 22 mm markers (DICT_4X4_50): an A4 print, 24 inner corners, seen
    at 40-70 px per square by a 640x480 D435 from 0.3-0.45 m.
    """

    squares_x: int = 5
    squares_y: int = 7
    square_m: float = 0.030
    marker_m: float = 0.022
    dictionary: str = "DICT_4X4_50"
    thickness_m: float = 0.003
    px_per_m: float = 8000.0  # texture resolution of the twin's print (8 px per mm)

    def __post_init__(self) -> None:
        if self.squares_x < 3 or self.squares_y < 3:
            raise BoardError("a ChArUco board needs at least 3 x 3 squares",
                             detail={"squares_x": self.squares_x, "squares_y": self.squares_y})
        if not (0 < self.marker_m < self.square_m) or not np.isfinite(self.square_m):
            raise BoardError("marker_m must be positive and smaller than square_m",
                             detail={"square_m": self.square_m, "marker_m": self.marker_m})
        if not hasattr(cv2.aruco, self.dictionary):
            raise BoardError(f"unknown ArUco dictionary {self.dictionary!r}", detail={"dictionary": self.dictionary})

    @property
    def size_m(self) -> tuple[float, float]:
        """(width along board x, height along board y) in metres."""
        return self.squares_x * self.square_m, self.squares_y * self.square_m

    @cached_property
    def board(self) -> cv2.aruco.CharucoBoard:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, d)

    @cached_property
    def corners_board(self) -> np.ndarray:
        """(N, 3) float64 inner chessboard corners in the board frame, indexed by ChArUco corner id."""
        return np.asarray(self.board.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)

    def image(self) -> np.ndarray:
        """The print as a (H, W, 3) uint8 RGB image, row 0 at the board's top edge (board y = 0)."""
        w, h = self.size_m
        size = (int(round(w * self.px_per_m)), int(round(h * self.px_per_m)))
        gray = self.board.generateImage(size, marginSize=0, borderBits=1)
        return np.ascontiguousarray(np.repeat(gray[:, :, None], 3, axis=2))

    @property
    def T_object_board(self) -> np.ndarray:
        """The board frame in the plate's object frame: origin at the top-left print corner on the top
        face, x along object +x, y along object -y, z down into the plate."""
        w, h = self.size_m
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = [-w / 2, h / 2, self.thickness_m]
        return T


@dataclass
class BoardDetection:
    """ChArUco corners found in one image: ids and sub-pixel (u, v), plus the board pose if solved."""

    ids: np.ndarray  # (N,) int
    pixels: np.ndarray  # (N, 2) float64
    T_camera_board: np.ndarray | None = None
    reprojection_px: float = float("nan")


def detect(spec: CharucoSpec, color: np.ndarray, K: np.ndarray, dist: np.ndarray | None = None,
           min_corners: int = 6) -> BoardDetection | None:
    """Find the board's corners in an RGB image and solve its pose (PnP on the corners).

    Returns None when fewer than ``min_corners`` corners are found (the board is out of view or too
    oblique): a calibration simply skips that view.
    """
    gray = cv2.cvtColor(np.ascontiguousarray(color), cv2.COLOR_RGB2GRAY)
    detector = cv2.aruco.CharucoDetector(spec.board)
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < min_corners:
        return None
    ids = ids.reshape(-1).astype(int)
    px = corners.reshape(-1, 2).astype(np.float64)
    obj = spec.corners_board[ids]
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, px, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, px, K, dist, rvec, tvec)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.reshape(3)
    proj = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((proj - px) ** 2, axis=1))))
    return BoardDetection(ids=ids, pixels=px, T_camera_board=T, reprojection_px=rms)


def board_plate_mesh(spec: CharucoSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (8, 3), triangles (12, 3), triangle_uvs (12, 3, 2), material ids (12,)) of the board as a
    thin plate in its object frame (bottom centre at the origin, z up). The top face carries the print
    (material 0, OBJ uv convention: v = 0 at the image bottom); sides and bottom are untextured (-1)."""
    w, h = spec.size_m
    t = spec.thickness_m
    x, y = w / 2, h / 2
    V = np.array([[-x, -y, 0], [x, -y, 0], [x, y, 0], [-x, y, 0],
                  [-x, -y, t], [x, -y, t], [x, y, t], [-x, y, t]], dtype=np.float64)
    top = [[4, 5, 6], [4, 6, 7]]
    rest = [[0, 2, 1], [0, 3, 2], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
            [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    F = np.array(top + rest, dtype=np.int32)

    def uv(v: np.ndarray) -> list[float]:  # board x = object x, board y = -object y; v = 1 at the top row
        return [(v[0] + x) / w, (v[1] + y) / h]

    uvs = np.zeros((len(F), 3, 2), dtype=np.float32)
    for i, tri in enumerate(top):
        uvs[i] = [uv(V[k]) for k in tri]
    mats = np.full(len(F), -1, dtype=np.int32)
    mats[:len(top)] = 0
    return V, F, uvs, mats
