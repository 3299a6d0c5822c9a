"""Measured differences between two renders of the same shot, in scene-linear values."""

from __future__ import annotations

import numpy as np

# Rec.709 luminance weights: both renders are scene-linear Rec.709.
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
ALPHA_MASK = 0.05


def luminance(rgba: np.ndarray) -> np.ndarray:
    return rgba[..., :3] @ LUMA


def compare(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Metrics of premultiplied RGBA image ``a`` (viewport) against reference ``b`` (Cycles).

    luminance_rel_error is sum|La - Lb| / sum Lb over pixels where either alpha exceeds 0.05: a mean
    relative error that does not explode on the few nearly black pixels a per-pixel ratio would.
    """
    if a.shape != b.shape:
        raise ValueError(f"images differ in size: {a.shape} vs {b.shape}")
    alpha_a, alpha_b = a[..., 3], b[..., 3]
    mask = (alpha_a > ALPHA_MASK) | (alpha_b > ALPHA_MASK)
    la, lb = luminance(a), luminance(b)
    inter = np.count_nonzero((alpha_a > ALPHA_MASK) & (alpha_b > ALPHA_MASK))
    union = np.count_nonzero(mask)
    ref_sum = float(lb[mask].sum()) if union else 0.0
    return {
        "alpha_rmse": float(np.sqrt(np.mean((alpha_a - alpha_b) ** 2))),
        "luminance_rel_error": float(np.abs(la - lb)[mask].sum() / ref_sum) if ref_sum > 0 else 0.0,
        "luminance_bias": float((la - lb)[mask].sum() / ref_sum) if ref_sum > 0 else 0.0,
        "silhouette_iou": float(inter / union) if union else 1.0,
        "coverage_a": float(np.mean(alpha_a > ALPHA_MASK)),
        "coverage_b": float(np.mean(alpha_b > ALPHA_MASK)),
        "mean_alpha_a": float(alpha_a.mean()),
        "mean_alpha_b": float(alpha_b.mean()),
        "mean_luminance_a": float(la.mean()),
        "mean_luminance_b": float(lb.mean()),
        "pixels_compared": int(union),
    }


def difference_image(a: np.ndarray, b: np.ndarray, gain: float = 4.0) -> np.ndarray:
    """Signed luminance difference as a display-ready RGB image: red where a is brighter, blue where darker."""
    d = (luminance(a) - luminance(b)) / max(float(luminance(b).max()), 1e-6) * gain
    out = np.zeros(a.shape[:2] + (4,), np.float32)
    out[..., 0] = np.clip(d, 0, 1)
    out[..., 2] = np.clip(-d, 0, 1)
    out[..., 1] = np.abs(a[..., 3] - b[..., 3]) * gain * 0.5
    out[..., 3] = 1.0
    return np.clip(out, 0, 1)


def side_by_side(*images: np.ndarray, gap: int = 4) -> np.ndarray:
    """Display-referred images (H, W, 4) placed left to right on a dark gutter."""
    h = max(im.shape[0] for im in images)
    w = sum(im.shape[1] for im in images) + gap * (len(images) - 1)
    out = np.full((h, w, 4), 0.08, np.float32)
    out[..., 3] = 1.0
    x = 0
    for im in images:
        out[: im.shape[0], x : x + im.shape[1], : im.shape[2]] = im
        x += im.shape[1] + gap
    return out
