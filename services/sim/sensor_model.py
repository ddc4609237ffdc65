"""A D435-like sensor model: what the real camera does to perfect depth and colour.

Stereo depth noise grows with the square of the distance: a disparity error of ``subpixel`` pixels at
focal length ``f`` (px) and baseline ``b`` (m) gives ``sigma_z = z^2 * subpixel / (f * b)``. The D435 has
a 50 mm baseline and ~0.08-0.1 px subpixel accuracy, no depth closer than ~0.28 m (min-Z at 640x480) and
none we trust beyond 3 m. At depth discontinuities the stereo matcher either gives up (dropouts, the
invalid band next to foreground edges) or blends foreground and background (flying pixels). Colour gets
per-pixel sensor noise and a small per-frame exposure change.

Everything is drawn from the ``rng`` passed in, so a frame is reproducible from its seed. Drawing ~1.5 M
fresh normal variates per 640x480 frame costs 20-30 ms on this machine, a third of the frame budget, so
per-pixel noise is read from fixed banks of pre-drawn variates at an offset the ``rng`` picks: each
frame's noise is still i.i.d. across its pixels and differs between frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from services.sim.errors import SimInputError


@dataclass(frozen=True)
class D435Noise:
    """Knobs of the sensor model; the defaults are the D435 at 640x480 as documented and observed."""

    baseline_m: float = 0.050
    subpixel: float = 0.08  # disparity RMS error in pixels (Intel quotes 0.08-0.1)
    min_depth_m: float = 0.28
    max_depth_m: float = 3.0
    dropout_prob: float = 0.003  # isolated invalid pixels anywhere
    edge_threshold_m: float = 0.02  # a neighbour this much farther/nearer makes a pixel an edge pixel
    edge_dropout_prob: float = 0.35  # edge pixels the matcher leaves invalid
    flying_pixel_prob: float = 0.25  # edge pixels blended between foreground and background
    color_sigma: float = 2.0  # per-channel colour noise, in 8-bit levels
    exposure_jitter: float = 0.01  # per-frame relative gain change (auto exposure)
    # pixels the second (right) imager cannot see have no depth: the band left of foreground edges and the
    # left image border (off by default: the defaults are the as-documented model; see ``calibrated``)
    stereo_occlusion: bool = False
    occlusion_dropout_prob: float = 1.0  # occluded pixels left invalid (the rest the matcher fills correctly)

    def __post_init__(self) -> None:
        probs = (self.dropout_prob, self.edge_dropout_prob, self.flying_pixel_prob, self.occlusion_dropout_prob)
        if any(not 0.0 <= p <= 1.0 for p in probs) or self.edge_dropout_prob + self.flying_pixel_prob > 1.0:
            raise SimInputError("noise probabilities must lie in [0, 1] (edge dropout + flying <= 1)",
                                code="bad_value")
        if self.baseline_m <= 0 or self.subpixel < 0 or self.color_sigma < 0 or self.exposure_jitter < 0:
            raise SimInputError("baseline must be positive, noise levels non-negative", code="bad_value")
        if not 0.0 <= self.min_depth_m < self.max_depth_m:
            raise SimInputError("need 0 <= min_depth_m < max_depth_m", code="bad_value")

    @classmethod
    def noiseless(cls) -> D435Noise:
        """The sensor's range limits and 1 mm quantisation only: no noise, dropouts or flying pixels."""
        return cls(subpixel=0.0, dropout_prob=0.0, edge_dropout_prob=0.0, flying_pixel_prob=0.0,
                   color_sigma=0.0, exposure_jitter=0.0)

    @classmethod
    def calibrated(cls) -> D435Noise:
        """The model fitted to real RealSense frames (``objscan bench sensor``, docs/sim.md "Calibration").

        Measured on 9 real 640x480 tabletop frames: the table's residual is ~1.5x the documented z^2 noise
        (subpixel 0.123 px, not 0.08), the invalid band left of foreground objects is the stereo occlusion
        (geometry alone matches its width, so few extra edge dropouts), flying pixels are rarer than the
        default assumed and random holes 6x rarer.
        """
        return cls(**CALIBRATED)

    def depth_sigma(self, z: np.ndarray | float, fx: float) -> np.ndarray | float:
        """Standard deviation of the depth noise (m) at depth ``z`` (m) for focal length ``fx`` (px)."""
        return np.square(z) * self.subpixel / (fx * self.baseline_m)


# fitted by ``bench/sensor.py`` (fit_noise) on ../shared/data/rgbd/tabletop_uoc; re-run it to refit
CALIBRATED: dict = {"subpixel": 0.123, "edge_dropout_prob": 0.019, "flying_pixel_prob": 0.093,
                     "dropout_prob": 0.0005, "stereo_occlusion": True}

_BANK_SIZE = 1 << 22
_BANKS: dict[str, np.ndarray] = {}


def _bank(kind: str) -> np.ndarray:
    """A fixed bank of 4 M float32 variates ("normal" or "uniform"), drawn once per process."""
    bank = _BANKS.get(kind)
    if bank is None:
        gen = np.random.default_rng(0x0D435 if kind == "normal" else 0x1D435)
        bank = (gen.standard_normal(_BANK_SIZE, dtype=np.float32) if kind == "normal"
                else gen.random(_BANK_SIZE, dtype=np.float32))
        bank.setflags(write=False)
        _BANKS[kind] = bank
    return bank


def noise_field(kind: str, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """``shape`` i.i.d. variates (standard "normal" or "uniform" in [0, 1)) read from a bank at an offset
    drawn from ``rng``: deterministic for the rng state, and ~20x cheaper than drawing them afresh."""
    n = int(np.prod(shape))
    bank = _bank(kind)
    if n > bank.size:
        gen = rng.standard_normal if kind == "normal" else rng.random
        return gen(shape, dtype=np.float32)
    off = int(rng.integers(0, bank.size - n + 1))
    return bank[off:off + n].reshape(shape)


def depth_edges(depth_m: np.ndarray, threshold_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Edge pixels and what a flying pixel there blends towards.

    Returns (edges, target): ``edges`` marks valid pixels with a 4-neighbour more than ``threshold_m``
    nearer or farther, or with a neighbour without data; ``target`` is the depth across the largest jump
    (0 where the only "jump" is to a pixel without data: nothing to blend with). Pixels outside the
    image count as copies of the border pixel.
    """
    depth = np.ascontiguousarray(depth_m, dtype=np.float32)
    edges = np.zeros(depth.shape, dtype=np.bool_)
    target = np.zeros(depth.shape, dtype=np.float32)
    _depth_edges(depth, np.float32(threshold_m), edges, target)
    return edges, target


@njit(cache=True, nogil=True)
def _depth_edges(depth, thr, edges, target):  # pragma: no cover - compiled
    h, w = depth.shape
    for r in range(h):
        for c in range(w):
            d = depth[r, c]
            if d <= 0:
                continue
            far = d
            near = d
            hole = False
            for k in range(4):
                rr = r + (k == 1) - (k == 0)
                cc = c + (k == 3) - (k == 2)
                rr = min(max(rr, 0), h - 1)
                cc = min(max(cc, 0), w - 1)
                e = depth[rr, cc]
                if e <= 0:
                    hole = True
                    continue
                if e > far:
                    far = e
                if e < near:
                    near = e
            far_jump = far - d
            near_jump = d - near
            if far_jump > thr or near_jump > thr:
                edges[r, c] = True
                target[r, c] = far if far_jump >= near_jump else near
            elif hole:
                edges[r, c] = True


def occluded(depth_m: np.ndarray, fx: float, baseline_m: float) -> np.ndarray:
    """Pixels the right imager does not see: another surface nearer the camera hides them from it, or they
    fall outside its image (the invalid band at the left border of D4xx depth).

    The depth imager is the left one; the right one sits ``baseline_m`` along +x. A pixel at column ``u``
    with disparity ``f b / z`` appears at ``u - f b / z`` in the right image; it is hidden when some pixel to
    its right lands at or left of that (nearer surfaces shift more), or when that is left of column 0.
    """
    depth = np.ascontiguousarray(depth_m, dtype=np.float32)
    out = np.zeros(depth.shape, dtype=np.bool_)
    _occluded(depth, np.float32(fx * baseline_m), out)
    return out


@njit(cache=True, nogil=True)
def _occluded(depth, fb, out):  # pragma: no cover - compiled
    h, w = depth.shape
    for r in range(h):
        lowest = np.float32(1e9)
        for c in range(w - 1, -1, -1):
            d = depth[r, c]
            if d <= 0:
                continue
            xr = np.float32(c) - fb / d
            if xr < -0.5 or xr > lowest:
                out[r, c] = True
            if xr < lowest:
                lowest = xr


def _edge_artifacts(depth: np.ndarray, noise: D435Noise, rng: np.random.Generator) -> None:
    """Flying pixels and dropouts at depth discontinuities, in place.

    An edge pixel becomes a flying pixel (a blend of the two surfaces, on either side of the edge) with
    ``flying_pixel_prob``, else drops out with ``edge_dropout_prob``; a pixel next to a hole has nothing
    to blend with and can only drop out.
    """
    edges, target = depth_edges(depth, noise.edge_threshold_m)
    u = noise_field("uniform", depth.shape, rng)
    fly = edges & (u < noise.flying_pixel_prob) & (target > 0)
    drop = edges & ~fly & (u < noise.flying_pixel_prob + noise.edge_dropout_prob)
    drop &= (u >= noise.flying_pixel_prob) | (target <= 0)
    if fly.any():
        t = rng.random(int(fly.sum()), dtype=np.float32)
        depth[fly] = depth[fly] + t * (target[fly] - depth[fly])
    depth[drop] = 0.0


def apply_d435_noise(depth_m: np.ndarray, color: np.ndarray, fx: float, noise: D435Noise,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Degrade perfect depth (float metres, 0 = no hit) and colour (uint8) as a D435 would.

    Returns (depth in metres, float32, 0 = no data; colour uint8). Order: stereo occlusion (on the
    perfect depth), flying pixels and dropouts at edges, random dropouts, z^2 stereo noise, then the range
    limits.
    """
    if depth_m.ndim != 2 or color.shape[:2] != depth_m.shape:
        raise SimInputError("depth must be (H, W) and colour (H, W, 3) of the same size", code="bad_shape")
    depth = np.asarray(depth_m, dtype=np.float32).copy()
    h, w = depth.shape
    hidden = occluded(depth, fx, noise.baseline_m) if noise.stereo_occlusion else None
    if noise.flying_pixel_prob > 0 or noise.edge_dropout_prob > 0:
        _edge_artifacts(depth, noise, rng)
    if hidden is not None:
        if noise.occlusion_dropout_prob < 1.0:
            hidden &= noise_field("uniform", (h, w), rng) < noise.occlusion_dropout_prob
        depth[hidden] = 0.0
    if noise.dropout_prob > 0:
        depth[noise_field("uniform", (h, w), rng) < noise.dropout_prob] = 0.0
    if noise.subpixel > 0:
        sigma = noise.depth_sigma(depth, fx).astype(np.float32)
        depth += sigma * noise_field("normal", (h, w), rng)
    depth[(depth < noise.min_depth_m) | (depth > noise.max_depth_m)] = 0.0

    out = color
    if noise.color_sigma > 0 or noise.exposure_jitter > 0:
        gain = 1.0 + noise.exposure_jitter * float(rng.standard_normal())
        c = color.astype(np.float32) * np.float32(gain)
        if noise.color_sigma > 0:
            c += np.float32(noise.color_sigma) * noise_field("normal", c.shape, rng)
        out = np.clip(c + 0.5, 0, 255).astype(np.uint8)
    return depth, out
