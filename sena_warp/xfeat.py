"""Sparse XFeat keypoints and descriptors on onnxruntime + numpy (docs/method.md step 0).

XFeat (Potje et al., CVPR 2024): the shipped ONNX backbone (``models/xfeat.onnx``, made by
``tools/export_xfeat.py``) gives, at 1/8 of the working resolution, 64-channel dense descriptors,
65-channel keypoint logits (an 8x8 cell plus a dustbin) and a reliability map. Everything after the
network is done here in numpy, following the reference ``XFeat.detectAndCompute``: softmax, drop the
dustbin, pixel-shuffle to full resolution, NMS, threshold, score = keypoint probability x
reliability, top-k, descriptors sampled from the 1/8 map and L2-normalised. No torch at run time.

Coordinates: points are ``(x, y)`` float64 in pixels; ``pts_work`` are in the resized working
image, ``pts`` returned to callers are in the input image.
"""

from __future__ import annotations

import functools
import importlib.resources
import os

import cv2
import numpy as np

from . import native_stderr
from .bilinear import sample_bilinear
from .config import Config
from .errors import InputError

with native_stderr.caught():  # its import says on stderr when HOME cannot keep its telemetry identifier
    import onnxruntime as ort

MODEL_FILE = "xfeat.onnx"
OUTPUT_NAMES = ("feats", "keypoint_logits", "reliability")
CELL = 8  # the backbone's output stride: one logit vector per 8x8 pixel cell
SIDE_MULTIPLE = 32  # the backbone's strides need both sides divisible by 32
NORM_EPS = 1e-12  # as torch.nn.functional.normalize
# Cubic convolution coefficient of torch's grid_sample(mode="bicubic"), which XFeat uses for
# descriptors; the network was trained and evaluated with that interpolation.
CUBIC_A = -0.75


def pool_spins(cfg: Config) -> bool:
    """Whether onnxruntime's intra-op pool spins while it waits for work. Only for a moving rig with a
    thread per core, its whole run as before: its re-estimates run beside the frame loop and land on
    their frame sooner. Anywhere else the spinning takes the core that the decoders and the
    estimate's numpy work need (the first estimate of a static rig is 0.25-0.3 s faster without it,
    image pairs take less CPU: see docs/benchmarks.md); with fewer threads than cores the process
    shares the machine."""
    return cfg.video_rig == "moving" and not 0 < cfg.cpu_threads < (os.cpu_count() or 1)


@functools.lru_cache(maxsize=2)
def xfeat_session(threads: int, spins: bool) -> ort.InferenceSession:
    """The ONNX backbone from the installed package, loaded once per thread count and spinning (CUDA
    provider when available).

    ``threads``: onnxruntime's intra-op threads (``Config.cpu_threads``; 0 = one per physical core);
    ``spins``: the pool spins while it waits for work (:func:`pool_spins`), as onnxruntime's default.
    """
    model = importlib.resources.files("sena_warp") / "models" / MODEL_FILE
    if not model.is_file():
        raise InputError(f"XFeat model {MODEL_FILE} is missing from the sena_warp package; reinstall it "
                         "or use --features sift")
    providers = ["CPUExecutionProvider"]
    if "CUDAExecutionProvider" in ort.get_available_providers():
        providers.insert(0, "CUDAExecutionProvider")
    options = ort.SessionOptions()
    # Fatal only: its errors (the CUDA provider's fallbacks, a failed allocation) come back as exceptions,
    # which the CLI says in one line; logged too, they were red lines on stderr before it.
    options.log_severity_level = 4
    options.intra_op_num_threads = threads
    if not spins:
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(model.read_bytes(), sess_options=options, providers=providers)


def working_size(shape_hw: tuple[int, int], max_side: int) -> tuple[int, int]:
    """(width, height) of the working image: long side <= max_side, both multiples of 32, never upscaled."""
    h, w = shape_hw
    scale = min(1.0, max_side / max(h, w))
    work_w = int(w * scale) // SIDE_MULTIPLE * SIDE_MULTIPLE
    work_h = int(h * scale) // SIDE_MULTIPLE * SIDE_MULTIPLE
    if work_w == 0 or work_h == 0:
        raise InputError(f"image {w}x{h} px is too small for XFeat at long side {max_side} px (needs "
                         f">= {SIDE_MULTIPLE} px per side); use --features sift")
    return work_w, work_h


def prepare_input(img_bgr: np.ndarray, work_wh: tuple[int, int]) -> np.ndarray:
    """BGR uint8 (H, W, 3) -> float32 (1, 3, h, w) in [0, 1], the model's input.

    The graph averages the channels and applies InstanceNorm itself (as XFeatModel.forward), so
    channel order does not matter. Shrinking uses area averaging to avoid aliasing.
    """
    if img_bgr.shape[1::-1] != work_wh:
        img_bgr = cv2.resize(img_bgr, work_wh, interpolation=cv2.INTER_AREA)
    return (img_bgr.astype(np.float32) / 255.0).transpose(2, 0, 1)[None]


def keypoint_heatmap(logits: np.ndarray) -> np.ndarray:
    """Keypoint logits (65, h, w) -> probability heatmap float32 (8h, 8w), indexed [y, x].

    Softmax over the 65 channels, drop the dustbin (last channel), and pixel-shuffle: channel
    ``8 * dy + dx`` of cell (i, j) is the probability of pixel (8i + dy, 8j + dx).
    """
    shifted = logits - logits.max(axis=0, keepdims=True)
    prob = np.exp(shifted)
    prob /= prob.sum(axis=0, keepdims=True)
    _, h, w = logits.shape
    cells = prob[: CELL * CELL].reshape(CELL, CELL, h, w)  # (dy, dx, i, j)
    return np.ascontiguousarray(cells.transpose(2, 0, 3, 1).reshape(h * CELL, w * CELL), dtype=np.float32)


def nms_peaks(heatmap: np.ndarray, size: int, threshold: float) -> np.ndarray:
    """Local maxima of ``heatmap`` (H, W) in a size x size window with value > threshold.

    Returns int64 (N, 2) ``(x, y)`` in row-major order. Plateaus keep every tied pixel, as XFeat's
    max-pool NMS does.
    """
    local_max = cv2.dilate(heatmap, np.ones((size, size), np.uint8))
    ys, xs = np.nonzero((heatmap == local_max) & (heatmap > threshold))
    return np.stack([xs, ys], axis=1).astype(np.int64)


def _cubic_taps(coord: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer tap positions and bicubic weights along one axis: (N, 4) each."""
    base = np.floor(coord)
    t = (coord - base)[:, None]

    def near(d):  # |d| <= 1
        return ((CUBIC_A + 2.0) * d - (CUBIC_A + 3.0)) * d * d + 1.0

    def far(d):  # 1 < |d| < 2
        return ((CUBIC_A * d - 5.0 * CUBIC_A) * d + 8.0 * CUBIC_A) * d - 4.0 * CUBIC_A

    weights = np.hstack([far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)])
    return base[:, None].astype(np.int64) + np.arange(-1, 3), weights


def sample_map(feature_map: np.ndarray, pts_work: np.ndarray, shape_work_hw: tuple[int, int],
               mode: str) -> np.ndarray:
    """Sample a (C, h, w) map at working-image points (N, 2) ``(x, y)``; returns float32 (N, C).

    Uses XFeat's convention (``InterpolateSparse2d``: the point normalised by (W - 1, H - 1), then
    ``grid_sample`` with align_corners=False), i.e. map column ``u = x * w / (W - 1) - 0.5``, with
    zeros outside the map. ``mode`` is "bilinear" or "bicubic".
    """
    c, h, w = feature_map.shape
    work_h, work_w = shape_work_hw
    u = pts_work[:, 0] * (w / (work_w - 1)) - 0.5
    v = pts_work[:, 1] * (h / (work_h - 1)) - 0.5
    if mode == "bilinear":
        # One cell of zeros around the map puts every footprint (u, v in [-0.5, size - 0.5]) inside it,
        # so the package's one bilinear rule reads grid_sample's zeros outside.
        padded = np.pad(feature_map, ((0, 0), (1, 1), (1, 1))).transpose(1, 2, 0)
        return sample_bilinear(padded, np.stack([u + 1.0, v + 1.0], axis=1)).astype(np.float32)
    cols, wx = _cubic_taps(u)
    rows, wy = _cubic_taps(v)
    pad = 2  # the bicubic kernel reaches 2 cells outside the map; padding with zeros as grid_sample
    # Channels last: each tap then gathers one point's C values from one place (a third less time).
    padded = np.pad(feature_map.transpose(1, 2, 0), ((pad, pad), (pad, pad), (0, 0)))
    cols = np.clip(cols + pad, 0, w + 2 * pad - 1)
    rows = np.clip(rows + pad, 0, h + 2 * pad - 1)
    out = np.zeros((len(pts_work), c), np.float64)
    for a in range(rows.shape[1]):
        for b in range(cols.shape[1]):
            out += (wy[:, a] * wx[:, b])[:, None] * padded[rows[:, a], cols[:, b]]
    return out.astype(np.float32)


def l2_normalise(x: np.ndarray, axis: int) -> np.ndarray:
    """x / max(||x||, eps) along ``axis`` (float32)."""
    norm = np.linalg.norm(x, axis=axis, keepdims=True)
    return (x / np.maximum(norm, NORM_EPS)).astype(np.float32)


def top_k_indices(scores: np.ndarray, k: int) -> np.ndarray:
    """Indices of the k highest scores, best first (stable: ties keep their order)."""
    return np.argsort(-scores, kind="stable")[:k]


def detect_xfeat(img_bgr: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sparse XFeat on a BGR uint8 (H, W, 3) image.

    Returns ``pts`` float64 (N, 2) ``(x, y)`` in input-image pixels, ``desc`` float32 (N, 64)
    L2-normalised, ``scores`` float32 (N,) = keypoint probability x reliability, best first;
    N <= cfg.xfeat_top_k (0 on an image without keypoints).
    """
    work_w, work_h = working_size(img_bgr.shape[:2], cfg.xfeat_max_side)
    session = xfeat_session(cfg.cpu_threads, pool_spins(cfg))
    feats, logits, reliability = session.run(list(OUTPUT_NAMES), {"image": prepare_input(img_bgr, (work_w, work_h))})
    heatmap = keypoint_heatmap(logits[0])
    pts_work = nms_peaks(heatmap, cfg.xfeat_nms_size, cfg.xfeat_detection_threshold).astype(np.float64)
    prob = heatmap[pts_work[:, 1].astype(np.int64), pts_work[:, 0].astype(np.int64)]
    scores = prob * sample_map(reliability[0], pts_work, (work_h, work_w), "bilinear")[:, 0]
    keep = top_k_indices(scores, cfg.xfeat_top_k)
    keep = keep[scores[keep] > 0]
    pts_work, scores = pts_work[keep], scores[keep]
    desc = l2_normalise(sample_map(l2_normalise(feats[0], axis=0), pts_work, (work_h, work_w), "bicubic"), axis=1)
    # Pixel centres: working pixel x covers input [x * s, (x + 1) * s), as cv2.resize samples.
    scale_xy = np.array([img_bgr.shape[1] / work_w, img_bgr.shape[0] / work_h])
    pts = (pts_work + 0.5) * scale_xy - 0.5
    return pts, desc, scores.astype(np.float32)
