"""Zhang-Suen thinning (vectorised NumPy) and splitting a skeleton into bounded pieces."""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from cablesim.checks import as_mask


def thinning(mask: np.ndarray, max_iter: int = 1000) -> np.ndarray:
    """One-pixel-wide skeleton of a binary mask (Zhang & Suen, 1984)."""
    mask = as_mask(mask)
    img = np.pad(mask.astype(np.uint8), 1)
    for _ in range(max_iter):
        changed = False
        for step in (0, 1):
            p = img
            p2, p3 = p[:-2, 1:-1], p[:-2, 2:]
            p4, p5 = p[1:-1, 2:], p[2:, 2:]
            p6, p7 = p[2:, 1:-1], p[2:, :-2]
            p8, p9 = p[1:-1, :-2], p[:-2, :-2]
            nb = [p2, p3, p4, p5, p6, p7, p8, p9]
            b = sum(n.astype(np.int16) for n in nb)
            a = sum(((nb[i] == 0) & (nb[(i + 1) % 8] == 1)).astype(np.int16) for i in range(8))
            if step == 0:
                c1 = (p2 * p4 * p6) == 0
                c2 = (p4 * p6 * p8) == 0
            else:
                c1 = (p2 * p4 * p8) == 0
                c2 = (p2 * p6 * p8) == 0
            centre = p[1:-1, 1:-1]
            rm = (centre == 1) & (b >= 2) & (b <= 6) & (a == 1) & c1 & c2
            if rm.any():
                changed = True
                centre[rm] = 0
        if not changed:
            break
    return img[1:-1, 1:-1].astype(bool)


_NB8 = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def split_skeleton(skel: np.ndarray, max_length: int) -> np.ndarray:
    """Label image (int32, 0 = none) cutting each skeleton branch every ``max_length`` pixels.

    Geodesic (8-connected BFS) distance from an end point of each connected component is
    binned by ``max_length``; each bin is split again into connected parts (branches).
    """
    skel = as_mask(skel)
    h, w = skel.shape
    dist = np.full((h, w), -1, np.int32)
    ncomp, comp = cv2.connectedComponents(skel.astype(np.uint8), connectivity=8)
    pts_by_comp: dict[int, list[tuple[int, int]]] = {}
    ys, xs = np.nonzero(skel)
    for y, x in zip(ys.tolist(), xs.tolist(), strict=True):
        pts_by_comp.setdefault(int(comp[y, x]), []).append((y, x))
    padded = np.pad(skel, 1)
    nbcount = sum(
        padded[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx].astype(np.int8) for dy, dx in _NB8
    )
    for _c, pts in pts_by_comp.items():
        ends = [p for p in pts if nbcount[p] == 1]
        start = min(ends) if ends else min(pts)
        dist[start] = 0
        dq = deque([start])
        while dq:
            y, x = dq.popleft()
            for dy, dx in _NB8:
                yy, xx = y + dy, x + dx
                if 0 <= yy < h and 0 <= xx < w and skel[yy, xx] and dist[yy, xx] < 0:
                    dist[yy, xx] = dist[y, x] + 1
                    dq.append((yy, xx))
    labels = np.zeros((h, w), np.int32)
    bins = np.where(skel, comp * 100000 + dist // max(1, int(max_length)), -1)
    next_label = 1
    for key in np.unique(bins[skel]):
        part = (bins == key).astype(np.uint8)
        n, lab = cv2.connectedComponents(part, connectivity=8)
        for i in range(1, n):
            labels[lab == i] = next_label
            next_label += 1
    return labels
