"""How the demo objects are made (``demo_objects.py`` lists them and keeps their files): closed, convex
triangle meshes in metres, z up, origin at the bottom centre of the footprint, with one texture atlas of
printed packaging drawn with OpenCV (fixed-seed generators and the built-in Hershey fonts only, so two runs
write the same bytes).

Every face carries its own print (brand text, logos, stripes, barcodes, small print): colour registration
needs texture to hold on to, and a can's label is the only thing that tells its turns apart. The sizes are
the groceries' and fit the RH-P12-RN's 106 mm stroke.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from services.sim.demo_files import MESH_FILE, MTL_FILE, TEXTURE_FILE

PX_PER_MM = 3.0  # texture resolution: 0.33 mm a texel, finer than the D435 sees at scan distance (~0.6 mm)
ATLAS_WIDTH = 1024
MARGIN_PX = 4  # each face's print is padded by its own edge so bilinear lookups never bleed across faces
FONT = cv2.FONT_HERSHEY_DUPLEX
FONT_BOLD = cv2.FONT_HERSHEY_TRIPLEX
FONT_SMALL = cv2.FONT_HERSHEY_SIMPLEX

RGB = tuple[int, int, int]
Painter = Callable[[int, int], np.ndarray]


# -- mesh and texture atlas -------------------------------------------------------------------------------

@dataclass
class _Face:
    """A planar face: corners (counter-clockwise seen from outside), their texture coordinates in the face's
    print (x right, y down, in pixels of the print) and the print's painter."""

    corners: list[tuple[float, float, float]]
    print_xy: list[tuple[float, float]]
    size_px: tuple[int, int]
    painter: Painter


class Mesh:
    """Faces collected in order; ``files()`` lays their prints into one atlas and writes OBJ/MTL/PNG."""

    def __init__(self) -> None:
        self.faces: list[_Face] = []

    def quad(self, origin, right, up, painter: Painter) -> None:  # noqa: ANN001 - 3-vectors as sequences
        """A rectangle from ``origin`` spanning ``right`` and ``up`` (``right x up`` points outward); its print
        appears upright when the face is seen from outside with ``up`` pointing up."""
        o, r, u = (np.asarray(a, dtype=np.float64) for a in (origin, right, up))
        w, h = _px(np.linalg.norm(r)), _px(np.linalg.norm(u))
        corners = [o, o + r, o + r + u, o + u]
        self.faces.append(_Face([tuple(c) for c in corners], [(0, h), (w, h), (w, 0), (0, 0)], (w, h), painter))

    def triangle(self, a, b, c, painter: Painter) -> None:  # noqa: ANN001
        """A triangle (counter-clockwise seen from outside) whose print is upright with ``a -> b`` along its
        bottom edge."""
        a, b, c = (np.asarray(p, dtype=np.float64) for p in (a, b, c))
        x_axis = (b - a) / np.linalg.norm(b - a)
        normal = np.cross(b - a, c - a)
        y_axis = np.cross(normal, x_axis)
        y_axis /= np.linalg.norm(y_axis)
        local = [(float(np.dot(p - a, x_axis)), float(np.dot(p - a, y_axis))) for p in (a, b, c)]
        xs = [p[0] for p in local]
        ys = [p[1] for p in local]
        x0, y_top = min(xs), max(ys)
        w, h = _px(max(xs) - x0), _px(y_top - min(ys))
        xy = [((x - x0) * 1000 * PX_PER_MM, (y_top - y) * 1000 * PX_PER_MM) for x, y in local]
        self.faces.append(_Face([tuple(a), tuple(b), tuple(c)], xy, (w, h), painter))

    def files(self) -> dict[str, bytes]:
        """The object's files: OBJ (shared positions, one texture coordinate per corner), MTL and PNG.

        Faces that share a painter share one print (a can's label spans all its side quads)."""
        prints: dict[int, int] = {}  # id(painter) -> index of its print
        sizes: list[tuple[int, int]] = []
        painters: list[Painter] = []
        for face in self.faces:
            if id(face.painter) not in prints:
                prints[id(face.painter)] = len(sizes)
                sizes.append(face.size_px)
                painters.append(face.painter)
        atlas, offsets = _pack(sizes)
        for painter, (w, h), (x0, y0) in zip(painters, sizes, offsets, strict=True):
            img = painter(w, h)
            if img.shape != (h, w, 3):
                raise ValueError(f"a face print is {img.shape}, expected {(h, w, 3)}")
            atlas[y0 - MARGIN_PX:y0 + h + MARGIN_PX, x0 - MARGIN_PX:x0 + w + MARGIN_PX] = cv2.copyMakeBorder(
                img, MARGIN_PX, MARGIN_PX, MARGIN_PX, MARGIN_PX, cv2.BORDER_REPLICATE)
        H, W = atlas.shape[:2]
        positions: dict[tuple[float, float, float], int] = {}
        v_lines: list[str] = []
        vt_lines: list[str] = []
        f_lines: list[str] = []
        for face in self.faces:
            x0, y0 = offsets[prints[id(face.painter)]]
            ids = []
            for corner, (px, py) in zip(face.corners, face.print_xy, strict=True):
                key = tuple(round(float(c), 9) + 0.0 for c in corner)
                if key not in positions:
                    positions[key] = len(positions) + 1
                    v_lines.append("v {:.6f} {:.6f} {:.6f}".format(*key))
                vt_lines.append(f"vt {(x0 + px) / W:.6f} {1.0 - (y0 + py) / H:.6f}")
                ids.append((positions[key], len(vt_lines)))
            for k in range(1, len(ids) - 1):  # a fan: quads and triangles are convex
                tri = (ids[0], ids[k], ids[k + 1])
                f_lines.append("f " + " ".join(f"{v}/{t}" for v, t in tri))
        obj = "\n".join(["# objscan demo object: generated by services/sim/demo_objects.py; metres, z up",
                         f"mtllib {MTL_FILE}", *v_lines, *vt_lines, "usemtl printed", *f_lines, ""])
        mtl = f"newmtl printed\nKd 1.0 1.0 1.0\nmap_Kd {TEXTURE_FILE}\n"
        ok, png = cv2.imencode(".png", cv2.cvtColor(atlas, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
        if not ok:  # pragma: no cover - OpenCV always encodes a uint8 RGB image
            raise RuntimeError("PNG encoding failed")
        return {MESH_FILE: obj.encode(), MTL_FILE: mtl.encode(), TEXTURE_FILE: png.tobytes()}


def _px(length_m: float) -> int:
    return max(8, int(round(length_m * 1000 * PX_PER_MM)))


def _pack(sizes: list[tuple[int, int]]) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Shelf packing of the prints (with margins) into an atlas ``ATLAS_WIDTH`` wide; (atlas, top-left of
    each print)."""
    x = y = shelf = 0
    offsets = []
    for w, h in sizes:
        W, H = w + 2 * MARGIN_PX, h + 2 * MARGIN_PX
        if W > ATLAS_WIDTH:
            raise ValueError(f"a face print of {w} px does not fit the atlas")
        if x + W > ATLAS_WIDTH:
            x, y, shelf = 0, y + shelf, 0
        offsets.append((x + MARGIN_PX, y + MARGIN_PX))
        x += W
        shelf = max(shelf, H)
    height = int(np.ceil((y + shelf) / 64.0) * 64)
    return np.full((height, ATLAS_WIDTH, 3), 255, dtype=np.uint8), offsets


# -- drawing helpers --------------------------------------------------------------------------------------

def _canvas(w: int, h: int, color: RGB) -> np.ndarray:
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = color
    return img


def _text(img: np.ndarray, text: str, center: tuple[float, float], height: float, color: RGB, *,
          font: int = FONT, thickness: int = 2, max_width: float | None = None) -> None:
    """``text`` centred at ``center`` with capitals ``height`` pixels tall (narrowed to ``max_width``)."""
    (tw, th), _ = cv2.getTextSize(text, font, 1.0, thickness)
    scale = height / max(th, 1)
    if max_width is not None and tw * scale > max_width:
        scale = max_width / tw
    (tw, th), _ = cv2.getTextSize(text, font, scale, thickness)
    org = (int(round(center[0] - tw / 2)), int(round(center[1] + th / 2)))
    cv2.putText(img, text, org, font, scale, color, thickness, cv2.LINE_AA)


def _small_print(img: np.ndarray, box: tuple[int, int, int, int], seed: int, color: RGB, line_px: int = 14) -> None:
    """Lines of pseudo-words (ingredients, nutrition facts) filling ``box`` = (x0, y0, x1, y1)."""
    rng = np.random.default_rng(seed)
    letters = "abcdefghiklmnoprstuvyz"
    x0, y0, x1, y1 = box
    y = y0 + line_px
    while y <= y1:
        words = []
        while sum(len(w) + 1 for w in words) < (x1 - x0) / (line_px * 0.55):
            words.append("".join(rng.choice(list(letters), size=int(rng.integers(2, 9)))))
        line = " ".join(words)
        (tw, th), _ = cv2.getTextSize(line, FONT_SMALL, 1.0, 1)
        scale = min((line_px * 0.62) / th, (x1 - x0) / tw)
        cv2.putText(img, line, (x0, y), FONT_SMALL, scale, color, 1, cv2.LINE_AA)
        y += line_px


def _nutrition_table(img: np.ndarray, box: tuple[int, int, int, int], seed: int, color: RGB) -> None:
    """A boxed table of label/value rows, like a nutrition panel."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = box
    cv2.rectangle(img, (x0, y0), (x1, y1), color, 2, cv2.LINE_AA)
    _text(img, "NUTRITION FACTS", ((x0 + x1) / 2, y0 + 16), 14, color, font=FONT_BOLD, thickness=2,
          max_width=(x1 - x0) - 10)
    cv2.line(img, (x0, y0 + 30), (x1, y0 + 30), color, 3)
    labels = ["Energy", "Fat", "Saturates", "Carbs", "Sugars", "Protein", "Salt", "Calcium", "Vitamin D", "Fibre"]
    y = y0 + 48
    for label in labels:
        if y > y1 - 6:
            break
        value = f"{rng.integers(1, 99)}.{rng.integers(0, 9)} g"
        _left_text(img, label, (x0 + 6, y), 10, color)
        (tw, _), _ = cv2.getTextSize(value, FONT_SMALL, 0.4, 1)
        _left_text(img, value, (x1 - 6 - int(tw * 1.0), y), 10, color)
        cv2.line(img, (x0 + 4, y + 6), (x1 - 4, y + 6), color, 1)
        y += 20


def _left_text(img: np.ndarray, text: str, org: tuple[int, int], height: float, color: RGB) -> None:
    (_, th), _ = cv2.getTextSize(text, FONT_SMALL, 1.0, 1)
    cv2.putText(img, text, org, FONT_SMALL, height / th, color, 1, cv2.LINE_AA)


def _barcode(img: np.ndarray, box: tuple[int, int, int, int], seed: int) -> None:
    """An EAN-like barcode (white field, black bars of 1-4 modules, digits under it)."""
    x0, y0, x1, y1 = box
    cv2.rectangle(img, (x0, y0), (x1, y1), (255, 255, 255), -1)
    rng = np.random.default_rng(seed)
    module = max(1, (x1 - x0 - 16) // 95)
    x = x0 + 8
    black = True
    while x < x1 - 8 - 4 * module:
        w = int(rng.integers(1, 5)) * module
        if black:
            cv2.rectangle(img, (x, y0 + 6), (x + w - 1, y1 - 20), (0, 0, 0), -1)
        x += w
        black = not black
    digits = "".join(str(d) for d in rng.integers(0, 10, size=13))
    _text(img, digits, ((x0 + x1) / 2, y1 - 10), 10, (0, 0, 0), font=FONT_SMALL, thickness=1,
          max_width=x1 - x0 - 12)


def _stripes(img: np.ndarray, box: tuple[int, int, int, int], colors: list[RGB], width: int, slant: int = 0) -> None:
    """Diagonal (``slant`` px over the box height) or straight vertical stripes cycling ``colors``."""
    x0, y0, x1, y1 = box
    sub = img[y0:y1, x0:x1]
    h, w = sub.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    band = ((xx + yy * slant / max(h, 1)) // width).astype(np.int64) % len(colors)
    sub[:] = np.asarray(colors, dtype=np.uint8)[band]


def _wave(img: np.ndarray, y_mid: float, amplitude: float, period: float, color: RGB, phase: float = 0.0) -> None:
    """Fill below a sine wave (a dairy carton's "milk splash" band)."""
    h, w = img.shape[:2]
    xs = np.arange(w + 1, dtype=np.float64)
    ys = y_mid + amplitude * np.sin(2 * np.pi * xs / period + phase)
    pts = np.concatenate([np.stack([xs, ys], axis=1), [[w, h], [0, h]]]).astype(np.int32)
    cv2.fillPoly(img, [pts], color, cv2.LINE_AA)


def _star(img: np.ndarray, center: tuple[float, float], r: float, color: RGB, points: int = 5) -> None:
    ang = np.pi / 2 + np.arange(2 * points) * np.pi / points
    rad = np.where(np.arange(2 * points) % 2 == 0, r, r * 0.45)
    pts = np.stack([center[0] + rad * np.cos(ang), center[1] - rad * np.sin(ang)], axis=1)
    cv2.fillPoly(img, [np.round(pts).astype(np.int32)], color, cv2.LINE_AA)


def _emblem(img: np.ndarray, center: tuple[float, float], r: float, ring: RGB, fill: RGB, text: str) -> None:
    """A round logo: ring, filled disc, a star and a word under it."""
    c = (int(round(center[0])), int(round(center[1])))
    cv2.circle(img, c, int(r), ring, -1, cv2.LINE_AA)
    cv2.circle(img, c, int(r * 0.84), fill, -1, cv2.LINE_AA)
    _star(img, (center[0], center[1] - r * 0.22), r * 0.38, ring)
    _text(img, text, (center[0], center[1] + r * 0.42), r * 0.2, ring, font=FONT_BOLD, thickness=1,
          max_width=r * 1.3)


def _seed(*parts: str) -> int:
    """A fixed seed per (object, face): stable across runs and Python versions (no ``hash``)."""
    return zlib.crc32("/".join(parts).encode())


# -- carton: a 1 l milk carton with a gable top -----------------------------------------------------------

CARTON_W = 0.070  # x: across the front panel (m)
CARTON_D = 0.070  # y
CARTON_BODY = 0.165  # height of the upright walls
CARTON_RIDGE = 0.195  # height of the gable's ridge (HOPE milk is 7.2 x 7.3 x 19.0 cm)

MILK_BLUE: RGB = (28, 78, 160)
MILK_SKY: RGB = (150, 200, 235)
MILK_RED: RGB = (200, 40, 45)
MILK_CREAM: RGB = (250, 248, 240)
MILK_GREEN: RGB = (40, 140, 70)


def _carton_front(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, MILK_CREAM)
    _wave(img, h * 0.72, h * 0.025, w * 0.9, MILK_SKY)
    _wave(img, h * 0.78, h * 0.02, w * 0.7, MILK_BLUE, phase=1.3)
    cv2.rectangle(img, (0, 0), (w, int(h * 0.06)), MILK_BLUE, -1)
    _text(img, "FRESH DAIRY", (w / 2, h * 0.03), h * 0.022, MILK_CREAM, thickness=1, max_width=w * 0.8)
    _emblem(img, (w * 0.5, h * 0.2), w * 0.24, MILK_RED, MILK_CREAM, "SINCE 1962")
    _text(img, "MEADOW", (w / 2, h * 0.38), h * 0.05, MILK_BLUE, font=FONT_BOLD, thickness=3, max_width=w * 0.9)
    _text(img, "WHOLE MILK", (w / 2, h * 0.47), h * 0.035, MILK_RED, thickness=2, max_width=w * 0.85)
    _text(img, "3.5% fat  pasteurised", (w / 2, h * 0.53), h * 0.016, MILK_BLUE, font=FONT_SMALL, thickness=1,
          max_width=w * 0.85)
    for k in range(3):  # three cows' worth of spots: dark blobs of fixed shape
        cx, cy = w * (0.25 + 0.25 * k), h * 0.62
        cv2.ellipse(img, (int(cx), int(cy)), (int(w * 0.08), int(h * 0.018)), 20 * k, 0, 360, (30, 30, 30), -1,
                    cv2.LINE_AA)
    _text(img, "1 L", (w * 0.5, h * 0.9), h * 0.05, MILK_CREAM, font=FONT_BOLD, thickness=3)
    return img


def _carton_back(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, MILK_CREAM)
    cv2.rectangle(img, (0, 0), (w, int(h * 0.08)), MILK_RED, -1)
    _text(img, "FROM OUR FARMS", (w / 2, h * 0.04), h * 0.024, MILK_CREAM, thickness=1, max_width=w * 0.85)
    _nutrition_table(img, (int(w * 0.08), int(h * 0.12), int(w * 0.92), int(h * 0.5)), _seed("carton", "back"),
                     MILK_BLUE)
    _small_print(img, (int(w * 0.08), int(h * 0.53), int(w * 0.92), int(h * 0.7)), _seed("carton", "back", "t"),
                 (60, 60, 60))
    _barcode(img, (int(w * 0.15), int(h * 0.73), int(w * 0.85), int(h * 0.86)), _seed("carton", "barcode"))
    _stripes(img, (0, int(h * 0.9), w, h), [MILK_BLUE, MILK_CREAM], 12, slant=24)
    return img


def _carton_left(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, MILK_SKY)
    _stripes(img, (0, 0, w, int(h * 0.25)), [MILK_BLUE, MILK_SKY, MILK_CREAM], 14, slant=30)
    _text(img, "KEEP", (w / 2, h * 0.32), h * 0.035, MILK_BLUE, font=FONT_BOLD, thickness=2)
    _text(img, "REFRIGERATED", (w / 2, h * 0.38), h * 0.02, MILK_BLUE, thickness=1, max_width=w * 0.9)
    cv2.rectangle(img, (int(w * 0.2), int(h * 0.43)), (int(w * 0.8), int(h * 0.55)), MILK_CREAM, -1)
    _text(img, "2-6 C", (w / 2, h * 0.49), h * 0.04, MILK_RED, font=FONT_BOLD, thickness=2)
    for k in range(6):  # a row of drops
        cx, cy = int(w * (0.12 + 0.152 * k)), int(h * 0.62)
        cv2.circle(img, (cx, cy), int(w * 0.05), MILK_CREAM, -1, cv2.LINE_AA)
        cv2.circle(img, (cx, cy - int(w * 0.05)), int(w * 0.02), MILK_CREAM, -1, cv2.LINE_AA)
    _small_print(img, (int(w * 0.08), int(h * 0.7), int(w * 0.92), int(h * 0.95)), _seed("carton", "left"),
                 MILK_BLUE)
    return img


def _carton_right(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, MILK_CREAM)
    cv2.rectangle(img, (0, int(h * 0.1)), (w, int(h * 0.3)), MILK_GREEN, -1)
    _text(img, "RECYCLE", (w / 2, h * 0.16), h * 0.03, MILK_CREAM, font=FONT_BOLD, thickness=2, max_width=w * 0.85)
    c = (w / 2, h * 0.24)
    for k in range(3):  # recycling arrows: three triangles around a circle
        a = np.pi / 2 + k * 2 * np.pi / 3
        tip = (c[0] + w * 0.1 * np.cos(a), c[1] - w * 0.1 * np.sin(a))
        base1 = (c[0] + w * 0.05 * np.cos(a + 0.9), c[1] - w * 0.05 * np.sin(a + 0.9))
        base2 = (c[0] + w * 0.05 * np.cos(a - 0.9), c[1] - w * 0.05 * np.sin(a - 0.9))
        cv2.fillPoly(img, [np.round([tip, base1, base2]).astype(np.int32)], MILK_CREAM, cv2.LINE_AA)
    _text(img, "BEST BEFORE", (w / 2, h * 0.36), h * 0.02, MILK_RED, thickness=1, max_width=w * 0.85)
    _text(img, "SEE TOP", (w / 2, h * 0.4), h * 0.018, MILK_RED, font=FONT_SMALL, thickness=1)
    _stripes(img, (0, int(h * 0.45), w, int(h * 0.6)), [MILK_RED, MILK_CREAM], 10)
    _small_print(img, (int(w * 0.08), int(h * 0.63), int(w * 0.92), int(h * 0.95)), _seed("carton", "right"),
                 (40, 40, 40))
    return img


def _carton_roof(label: str, color: RGB) -> Painter:
    def paint(w: int, h: int) -> np.ndarray:
        img = _canvas(w, h, color)
        _stripes(img, (0, int(h * 0.75), w, h), [MILK_CREAM, color], 8, slant=16)
        _text(img, label, (w / 2, h * 0.4), h * 0.16, MILK_CREAM, font=FONT_BOLD, thickness=2, max_width=w * 0.85)
        return img
    return paint


def _carton_gable(color: RGB, mark: str) -> Painter:
    def paint(w: int, h: int) -> np.ndarray:
        img = _canvas(w, h, color)
        _text(img, mark, (w / 2, h * 0.7), h * 0.28, MILK_CREAM, font=FONT_BOLD, thickness=2, max_width=w * 0.4)
        return img
    return paint


def _carton_bottom(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, (205, 200, 190))
    cv2.rectangle(img, (6, 6), (w - 7, h - 7), (120, 115, 110), 2)
    _text(img, "LOT 0412", (w / 2, h / 2), h * 0.1, (60, 60, 60), thickness=1, max_width=w * 0.8)
    return img


def build_carton() -> Mesh:
    W, D, H, R = CARTON_W, CARTON_D, CARTON_BODY, CARTON_RIDGE
    m = Mesh()
    x0, x1, y0, y1 = -W / 2, W / 2, -D / 2, D / 2
    m.quad((x0, y0, 0), (W, 0, 0), (0, 0, H), _carton_front)  # -y: the front
    m.quad((x1, y0, 0), (0, D, 0), (0, 0, H), _carton_right)  # +x
    m.quad((x1, y1, 0), (-W, 0, 0), (0, 0, H), _carton_back)  # +y
    m.quad((x0, y1, 0), (0, -D, 0), (0, 0, H), _carton_left)  # -x
    m.quad((x0, y1, 0), (W, 0, 0), (0, -D, 0), _carton_bottom)  # -z
    m.quad((x0, y0, H), (W, 0, 0), (0, D / 2, R - H), _carton_roof("OPEN HERE", MILK_BLUE))  # ridge along x
    m.quad((x1, y1, H), (-W, 0, 0), (0, -D / 2, R - H), _carton_roof("MEADOW", MILK_RED))
    m.triangle((x1, y0, H), (x1, y1, H), (x1, 0, R), _carton_gable(MILK_GREEN, "A"))
    m.triangle((x0, y1, H), (x0, y0, H), (x0, 0, R), _carton_gable(MILK_BLUE, "B"))
    return m


# -- can: a 400 g food can --------------------------------------------------------------------------------

CAN_RADIUS = 0.0365  # m (7.3 cm across, like a 400 g can)
CAN_HEIGHT = 0.110
CAN_SEGMENTS = 96

SOUP_RED: RGB = (185, 30, 35)
SOUP_GOLD: RGB = (235, 185, 50)
SOUP_WHITE: RGB = (248, 244, 236)
SOUP_GREEN: RGB = (50, 120, 50)
SOUP_BROWN: RGB = (90, 50, 30)


def _can_label(w: int, h: int) -> np.ndarray:
    """The whole wrap-around label; every quarter of the circumference prints something different."""
    img = _canvas(w, h, SOUP_WHITE)
    cv2.rectangle(img, (0, 0), (w, int(h * 0.14)), SOUP_RED, -1)
    cv2.rectangle(img, (0, int(h * 0.86)), (w, h), SOUP_RED, -1)
    _stripes(img, (0, int(h * 0.14), w, int(h * 0.18)), [SOUP_GOLD, SOUP_RED], 10, slant=12)
    _stripes(img, (0, int(h * 0.82), w, int(h * 0.86)), [SOUP_GOLD, SOUP_RED], 10, slant=-12)
    q = w // 4
    # quarter 1: brand and product
    _text(img, "HARVEST", (q * 0.5, h * 0.3), h * 0.09, SOUP_RED, font=FONT_BOLD, thickness=3, max_width=q * 0.9)
    _text(img, "TOMATO SOUP", (q * 0.5, h * 0.45), h * 0.05, SOUP_BROWN, thickness=2, max_width=q * 0.9)
    for k in range(3):  # tomatoes
        c = (int(q * (0.25 + 0.25 * k)), int(h * 0.64))
        cv2.circle(img, c, int(h * 0.07), SOUP_RED, -1, cv2.LINE_AA)
        cv2.circle(img, (c[0] - int(h * 0.02), c[1] - int(h * 0.02)), int(h * 0.015), (245, 130, 120), -1,
                   cv2.LINE_AA)
        _star(img, (c[0], c[1] - h * 0.06), h * 0.025, SOUP_GREEN)
    # quarter 2: the emblem and weight
    _emblem(img, (q * 1.5, h * 0.42), h * 0.2, SOUP_GOLD, SOUP_RED, "QUALITY")
    _text(img, "400 g", (q * 1.5, h * 0.74), h * 0.07, SOUP_BROWN, font=FONT_BOLD, thickness=2)
    # quarter 3: nutrition panel and small print
    _nutrition_table(img, (int(q * 2.06), int(h * 0.22), int(q * 2.94), int(h * 0.62)), _seed("can", "nutrition"),
                     SOUP_BROWN)
    _small_print(img, (int(q * 2.06), int(h * 0.65), int(q * 2.94), int(h * 0.8)), _seed("can", "text"),
                 (50, 50, 50))
    # quarter 4: barcode, serving suggestion band
    cv2.rectangle(img, (3 * q, int(h * 0.2)), (w, int(h * 0.4)), SOUP_GREEN, -1)
    _text(img, "READY IN 5 MIN", (q * 3.5, h * 0.3), h * 0.045, SOUP_WHITE, thickness=2, max_width=q * 0.85)
    _barcode(img, (int(q * 3.15), int(h * 0.48), int(q * 3.85), int(h * 0.76)), _seed("can", "barcode"))
    _text(img, "HARVEST  *  HARVEST  *  HARVEST  *  HARVEST", (w / 2, h * 0.07), h * 0.05, SOUP_WHITE,
          thickness=2, max_width=w * 0.95)
    _text(img, "SERVE HOT  -  STIR WELL  -  SERVE HOT  -  STIR WELL", (w / 2, h * 0.93), h * 0.04, SOUP_GOLD,
          thickness=1, max_width=w * 0.95)
    return img


def _can_lid(label: str) -> Painter:
    def paint(w: int, h: int) -> np.ndarray:
        img = _canvas(w, h, (175, 178, 182))
        c = (w // 2, h // 2)
        for k, shade in enumerate((150, 195, 160, 205, 170)):  # pressed rings of a tin lid
            cv2.circle(img, c, int(w * (0.48 - 0.07 * k)), (shade, shade + 2, shade + 5), 3, cv2.LINE_AA)
        _text(img, label, (w / 2, h / 2), h * 0.07, (70, 70, 75), thickness=1, max_width=w * 0.5)
        return img
    return paint


def build_can() -> Mesh:
    R, H, N = CAN_RADIUS, CAN_HEIGHT, CAN_SEGMENTS
    m = Mesh()
    ang = 2 * np.pi * np.arange(N + 1) / N
    ring = [(R * float(np.cos(a)), R * float(np.sin(a))) for a in ang[:N]] + [(R, 0.0)]
    label_w, label_h = _px(2 * np.pi * R), _px(H)
    for i in range(N):
        (xa, ya), (xb, yb) = ring[i], ring[i + 1]
        u0, u1 = label_w * i / N, label_w * (i + 1) / N
        m.faces.append(_Face([(xa, ya, 0.0), (xb, yb, 0.0), (xb, yb, H), (xa, ya, H)],
                             [(u0, label_h), (u1, label_h), (u1, 0), (u0, 0)], (label_w, label_h),
                             _can_label))
    lid = _px(2 * R)
    for z, painter, flip in ((H, _can_lid("HARVEST"), False), (0.0, _can_lid("BEST BEFORE 2029"), True)):
        for i in range(N):
            (xa, ya), (xb, yb) = ring[i], ring[i + 1]
            corners = [(0.0, 0.0, z), (xa, ya, z), (xb, yb, z)]
            if flip:  # the bottom lid faces down: reverse the winding
                corners = [corners[0], corners[2], corners[1]]
            uv = [((x / R + 1) * lid / 2, (1 - y / R) * lid / 2) for x, y, _ in corners]
            m.faces.append(_Face(corners, uv, (lid, lid), painter))
    return m


# -- flat box: a box of crackers lying flat ---------------------------------------------------------------

FLAT_L = 0.130  # x (m)
FLAT_W = 0.075  # y: what the gripper closes across
FLAT_H = 0.045  # z

CRACK_ORANGE: RGB = (230, 120, 30)
CRACK_BROWN: RGB = (110, 60, 25)
CRACK_CREAM: RGB = (252, 236, 200)
CRACK_TEAL: RGB = (20, 120, 130)


def _flat_top(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, CRACK_ORANGE)
    cv2.rectangle(img, (0, int(h * 0.72)), (w, h), CRACK_BROWN, -1)
    _text(img, "CRISPY", (w * 0.38, h * 0.22), h * 0.16, CRACK_CREAM, font=FONT_BOLD, thickness=3,
          max_width=w * 0.6)
    _text(img, "CRACKERS", (w * 0.38, h * 0.45), h * 0.12, CRACK_BROWN, font=FONT_BOLD, thickness=2,
          max_width=w * 0.6)
    for i in range(3):  # crackers: squares with dimples
        for j in range(2):
            x0, y0 = int(w * (0.72 + 0.09 * i)) - 18, int(h * (0.1 + 0.22 * j))
            cv2.rectangle(img, (x0, y0), (x0 + 34, y0 + 34), (220, 175, 100), -1)
            cv2.rectangle(img, (x0, y0), (x0 + 34, y0 + 34), CRACK_BROWN, 1)
            for a in range(3):
                for b in range(3):
                    cv2.circle(img, (x0 + 8 + 9 * a, y0 + 8 + 9 * b), 2, CRACK_BROWN, -1)
    _text(img, "SEA SALT  -  BAKED NOT FRIED", (w / 2, h * 0.6), h * 0.06, CRACK_CREAM, thickness=1,
          max_width=w * 0.9)
    _text(img, "250 g", (w * 0.85, h * 0.86), h * 0.09, CRACK_CREAM, font=FONT_BOLD, thickness=2)
    _emblem(img, (w * 0.12, h * 0.86), h * 0.12, CRACK_CREAM, CRACK_TEAL, "NEW")
    return img


def _flat_bottom(w: int, h: int) -> np.ndarray:
    img = _canvas(w, h, CRACK_CREAM)
    _nutrition_table(img, (int(w * 0.04), int(h * 0.08), int(w * 0.45), int(h * 0.92)), _seed("flat", "nutrition"),
                     CRACK_BROWN)
    _small_print(img, (int(w * 0.5), int(h * 0.08), int(w * 0.96), int(h * 0.55)), _seed("flat", "text"),
                 (60, 40, 20))
    _barcode(img, (int(w * 0.55), int(h * 0.6), int(w * 0.92), int(h * 0.92)), _seed("flat", "barcode"))
    return img


def _flat_side(title: str, base: RGB, accent: RGB, seed: str) -> Painter:
    def paint(w: int, h: int) -> np.ndarray:
        img = _canvas(w, h, base)
        _stripes(img, (0, 0, w, int(h * 0.22)), [accent, base], 9, slant=14)
        _stripes(img, (0, int(h * 0.8), w, h), [accent, base], 9, slant=-14)
        _text(img, title, (w / 2, h * 0.5), h * 0.28, CRACK_CREAM, font=FONT_BOLD, thickness=2, max_width=w * 0.85)
        if w > h * 2.5:  # the long sides also get a checker band and a number
            for k in range(int(w * 0.12 // 8)):
                color = CRACK_CREAM if k % 2 == 0 else accent
                cv2.rectangle(img, (8 + 8 * k, int(h * 0.68)), (15 + 8 * k, int(h * 0.76)), color, -1)
            _text(img, str(_seed(seed) % 900 + 100), (w * 0.92, h * 0.72), h * 0.1, CRACK_CREAM, thickness=1)
        return img
    return paint


def build_flat_box() -> Mesh:
    L, W, H = FLAT_L, FLAT_W, FLAT_H
    m = Mesh()
    x0, x1, y0, y1 = -L / 2, L / 2, -W / 2, W / 2
    m.quad((x0, y0, 0), (L, 0, 0), (0, 0, H), _flat_side("CRISPY CRACKERS", CRACK_TEAL, CRACK_ORANGE, "front"))
    m.quad((x1, y0, 0), (0, W, 0), (0, 0, H), _flat_side("SALT", CRACK_BROWN, CRACK_ORANGE, "right"))
    m.quad((x1, y1, 0), (-L, 0, 0), (0, 0, H), _flat_side("BAKED DAILY", CRACK_ORANGE, CRACK_BROWN, "back"))
    m.quad((x0, y1, 0), (0, -W, 0), (0, 0, H), _flat_side("250g", CRACK_TEAL, CRACK_CREAM, "left"))
    m.quad((x0, y0, H), (L, 0, 0), (0, W, 0), _flat_top)
    m.quad((x0, y1, 0), (L, 0, 0), (0, -W, 0), _flat_bottom)
    return m


#: What builds each demo object, by name.
BUILDERS: dict[str, Callable[[], Mesh]] = {"carton": build_carton, "can": build_can, "flat_box": build_flat_box}
