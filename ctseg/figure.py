"""Pictures of a segmentation as PNG, drawn with numpy alone (no display, no matplotlib).

The paper's Fig. 5 in six panels: input, density map, CVT regions with sites, Delaunay mesh
over the image, mesh coloured by material, material boundaries over the input.
"""
import struct
import zlib

import numpy as np

from .errors import InputError

# Material colours: colour-blind-safe (Okabe-Ito), air first.
PALETTE = np.array([
    [40, 40, 40], [230, 159, 0], [86, 180, 233], [0, 158, 115], [240, 228, 66],
    [0, 114, 178], [213, 94, 0], [204, 121, 167], [150, 150, 150],
], np.uint8)


def write_png(path, rgb):
    """Write an (h, w, 3) uint8 array as a PNG file."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"write_png: expected (h, w, 3) pixels, got {rgb.shape}")
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[r].tobytes() for r in range(h))

    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    with open(path, "wb") as fh:
        fh.write(png)


def gray_rgb(image, low_pct=0.5, high_pct=99.5):
    img = np.asarray(image, float)
    lo, hi = np.percentile(img, [low_pct, high_pct])
    g = np.clip((img - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
    return np.repeat((g * 255).astype(np.uint8)[:, :, None], 3, axis=2)


def _upscale(rgb, s):
    return np.repeat(np.repeat(rgb, s, axis=0), s, axis=1)


def draw_segments(rgb, p0, p1, color, scale):
    """Draw line segments (pixel coordinates x, y) onto an image upscaled by ``scale``."""
    h, w, _ = rgb.shape
    p0 = (np.asarray(p0, float) + 0.5) * scale - 0.5
    p1 = (np.asarray(p1, float) + 0.5) * scale - 0.5
    length = np.hypot(*(p1 - p0).T)
    nsamp = np.maximum(2, np.ceil(length * 1.5).astype(int))
    idx = np.repeat(np.arange(len(p0)), nsamp)
    t = np.concatenate([np.linspace(0, 1, k) for k in nsamp]) if len(nsamp) else np.zeros(0)
    pts = p0[idx] + t[:, None] * (p1[idx] - p0[idx])
    c = np.clip(np.round(pts[:, 0]).astype(int), 0, w - 1)
    r = np.clip(np.round(pts[:, 1]).astype(int), 0, h - 1)
    rgb[r, c] = color
    return rgb


def label_rgb(labels):
    lab = np.asarray(labels, np.int64)
    return PALETTE[lab % len(PALETTE)]


def segmentation_figure(path, image, seg, scale=None):
    """Render the six panels of the paper's Fig. 5 for a :class:`ctseg.SegmentedMesh`."""
    from .metrics import label_image

    img = np.asarray(image, float)
    rows, cols = img.shape
    if scale is None:
        scale = max(1, int(round(400 / max(rows, cols))))
    base = _upscale(gray_rgb(img), scale)
    dens = _upscale(gray_rgb(seg.density, 0, 100), scale)
    # CVT regions: random pastel colours, sites as dots
    rng = np.random.default_rng(0)
    cols_rand = rng.integers(90, 255, (seg.cvt_labels.max() + 1, 3)).astype(np.uint8)
    cvt = _upscale(cols_rand[seg.cvt_labels], scale)
    sp = np.clip(np.round((seg.points + 0.5) * scale - 0.5).astype(int), 0, [cols * scale - 1, rows * scale - 1])
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            cvt[np.clip(sp[:, 1] + dr, 0, rows * scale - 1), np.clip(sp[:, 0] + dc, 0, cols * scale - 1)] = 0
    t = seg.triangles
    e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    mesh = draw_segments(base.copy(), seg.points[e[:, 0]], seg.points[e[:, 1]], (255, 60, 60), scale)
    mat = _upscale(label_rgb(label_image(seg.points, seg.triangles, seg.material, img.shape)), scale)
    mat = draw_segments(mat, seg.points[e[:, 0]], seg.points[e[:, 1]], (0, 0, 0), scale)
    bnd = draw_segments(base.copy(), seg.points[seg.boundary_edges[:, 0]],
                        seg.points[seg.boundary_edges[:, 1]], (255, 40, 40), scale)
    gap = 6
    H, W = rows * scale, cols * scale
    canvas = np.full((2 * H + 3 * gap, 3 * W + 4 * gap, 3), 255, np.uint8)
    for k, panel in enumerate([base, dens, cvt, mesh, mat, bnd]):
        r0 = gap + (k // 3) * (H + gap)
        c0 = gap + (k % 3) * (W + gap)
        canvas[r0:r0 + H, c0:c0 + W] = panel
    write_png(path, canvas)
    return canvas
