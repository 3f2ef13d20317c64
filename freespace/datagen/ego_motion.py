"""The camera's motion along a drive, for propagation (:mod:`freespace.datagen.propagate`, step 1): ORB features of
the earlier left image with a disparity (SGBM or LiDAR) are points in 3-D; their matches in the next left image give
the motion by PnP (RANSAC, then Levenberg–Marquardt on the inliers). Motions are chained along the drive, and the
later frames a frame takes labels from are picked by how far the camera travelled (:func:`source_frames`).

Conventions: pixels 0-based (``u`` column, ``v`` row); camera frame x right, y down, z forward, metres;
:class:`Motion` maps points of the earlier camera into the later one. NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from freespace.datagen.options import PropagateOptions

__all__ = ["Motion", "compose", "ego_motion", "source_frames", "grey"]


@dataclass(frozen=True)
class Motion:
    """A rigid motion of the camera: points of the earlier camera frame in the later one, ``X_s = R X_t + t``.

    Attributes:
        R: 3×3 rotation. t: 3-vector, metres. inliers: PnP inliers it rests on (0 for a composed motion).
    """

    R: np.ndarray
    t: np.ndarray
    inliers: int = 0

    @property
    def travel(self) -> float:
        """The distance the camera centre moved, metres."""
        return float(np.linalg.norm(self.R.T @ self.t))


def compose(first: Motion, then: Motion) -> Motion:
    """``then ∘ first``: the motion from ``first``'s earlier frame to ``then``'s later one (inliers: the fewer)."""
    return Motion(then.R @ first.R, then.R @ first.t + then.t, min(first.inliers, then.inliers))


def grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def ego_motion(earlier: np.ndarray, later: np.ndarray, disparity: np.ndarray, K: np.ndarray, baseline: float, *,
               options: PropagateOptions = PropagateOptions(), features: int = 3000) -> Motion | None:
    """The camera's motion from the earlier left image to the later one, or None when it cannot be trusted.

    Args:
        earlier, later: ``H×W×3`` RGB (or ``H×W`` grey) ``uint8`` left images of one camera.
        disparity: ``float32 H×W`` disparity of ``earlier`` in pixels (NaN or ≤ 0: none; sparse LiDAR is enough).
        K: 3×3 intrinsics (pixels). baseline: metres (> 0), for the depth of a disparity.
        options: ``max_depth`` and ``min_inliers``. features: ORB features detected per image.

    Returns:
        ``Motion`` with ``X_later = R X_earlier + t`` (metres) and its PnP inlier count, or None with fewer than
        ``options.min_inliers`` inliers (a blank image, a stopped frame that matched nothing, a scene cut).
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    orb = cv2.ORB_create(features)
    ga, gb = grey(earlier), grey(later)
    with np.errstate(invalid="ignore"):
        has_depth = np.isfinite(disparity) & (disparity >= fx * baseline / options.max_depth)
    kp_a, des_a = orb.detectAndCompute(ga, (cv2.dilate(has_depth.astype(np.uint8), np.ones((5, 5))) > 0)
                                       .astype(np.uint8) * 255)
    kp_b, des_b = orb.detectAndCompute(gb, None)
    if des_a is None or des_b is None or len(kp_a) < options.min_inliers:
        return None
    matches = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(des_a, des_b, k=2)
    good = [m[0] for m in matches if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
    obj, img = [], []
    for m in good:
        u, v = kp_a[m.queryIdx].pt
        d = _nearest_disparity(disparity, has_depth, u, v)
        if d is None:
            continue
        z = fx * baseline / d
        obj.append(((u - cx) * z / fx, (v - cy) * z / fy, z))
        img.append(kp_b[m.trainIdx].pt)
    if len(obj) < options.min_inliers:
        return None
    obj_a, img_b = np.asarray(obj, np.float64), np.asarray(img, np.float64)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(obj_a, img_b, K, None, iterationsCount=300, reprojectionError=2.0,
                                                 confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not ok or inliers is None or len(inliers) < options.min_inliers:
        return None
    idx = inliers.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(obj_a[idx], img_b[idx], K, None, rvec, tvec)
    return Motion(cv2.Rodrigues(rvec)[0], tvec.ravel(), int(len(idx)))


def _nearest_disparity(disparity: np.ndarray, has: np.ndarray, u: float, v: float, radius: int = 2) -> float | None:
    """The disparity at (u, v), or the median of those within ``radius`` pixels (sparse LiDAR), or None."""
    h, w = disparity.shape
    c, r = int(round(u)), int(round(v))
    if 0 <= r < h and 0 <= c < w and has[r, c]:
        return float(disparity[r, c])
    r0, r1, c0, c1 = max(r - radius, 0), min(r + radius + 1, h), max(c - radius, 0), min(c + radius + 1, w)
    near = disparity[r0:r1, c0:c1][has[r0:r1, c0:c1]]
    return float(np.median(near)) if near.size else None


def source_frames(motions: list[Motion | None], t: int, options: PropagateOptions = PropagateOptions()
                  ) -> list[tuple[int, Motion]]:
    """The later frames that frame ``t`` takes labels from, with the motion from ``t`` to each.

    Args:
        motions: ``motions[i]`` from frame ``i`` to ``i + 1`` of one drive (None: not trusted — the chain stops).
        t: the frame.

    Returns:
        Up to ``options.sources`` pairs ``(s, motion)`` with ``t < s ≤ t + window`` and a travel within
        ``[min_travel, max_travel]``, spread evenly over the candidates (nearest and farthest included).
    """
    candidates, motion = [], None
    for s in range(t + 1, min(t + options.window, len(motions)) + 1):
        step = motions[s - 1]
        if step is None:
            break
        motion = step if motion is None else compose(motion, step)
        if motion.travel > options.max_travel:
            break
        if motion.travel >= options.min_travel:
            candidates.append((s, motion))
    if len(candidates) <= options.sources:
        return candidates
    picks = np.unique(np.round(np.linspace(0, len(candidates) - 1, options.sources)).astype(int))
    return [candidates[i] for i in picks]
