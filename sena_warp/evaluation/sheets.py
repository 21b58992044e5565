"""Contact sheets: labelled thumbnails of panoramas tiled into one picture, to look at many results at once."""

from __future__ import annotations

import math

import cv2
import numpy as np

BACKGROUND_GREY = 64  # behind transparent panorama pixels, so uncovered corners stay visible
LABEL_H_PX = 22  # height of the label strip above each thumbnail
LABEL_SCALE = 0.45  # cv2.putText font scale of the labels


def thumbnail(image: np.ndarray | None, label: str, box_wh: tuple[int, int]) -> np.ndarray:
    """A (box_h + LABEL_H_PX, box_w, 3) uint8 cell: ``image`` fitted into the box under its label.

    ``image``: BGR or BGRA uint8 (alpha 0 = uncovered, drawn grey); None draws an empty (black) box,
    for a method that produced no panorama (say why in the label).
    """
    box_w, box_h = box_wh
    cell = np.zeros((box_h + LABEL_H_PX, box_w, 3), np.uint8)
    if image is not None:
        flat = image[:, :, :3].astype(np.float32)
        if image.shape[2] == 4:
            alpha = image[:, :, 3:4].astype(np.float32) / 255.0
            flat = flat * alpha + BACKGROUND_GREY * (1.0 - alpha)
        scale = min(box_w / flat.shape[1], box_h / flat.shape[0])
        size = (max(1, round(flat.shape[1] * scale)), max(1, round(flat.shape[0] * scale)))
        small = cv2.resize(flat.astype(np.uint8), size, interpolation=cv2.INTER_AREA)
        cell[LABEL_H_PX:LABEL_H_PX + small.shape[0], :small.shape[1]] = small
    cv2.putText(cell, label, (4, LABEL_H_PX - 7), cv2.FONT_HERSHEY_SIMPLEX, LABEL_SCALE, (255, 255, 255), 1,
                cv2.LINE_AA)
    return cell


def tile(cells: list[np.ndarray], columns: int) -> np.ndarray:
    """Cells of equal shape tiled ``columns`` across, row-major; empty slots black."""
    rows = math.ceil(len(cells) / columns)
    blank = np.zeros_like(cells[0])
    padded = cells + [blank] * (rows * columns - len(cells))
    return np.vstack([np.hstack(padded[r * columns:(r + 1) * columns]) for r in range(rows)])
