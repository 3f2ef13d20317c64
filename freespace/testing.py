"""Small generated inputs for tests of freespace and of code built on it (the product's tests, the studies' tests):
a smooth texture, a frame with a road in it and a tiny trained road checkpoint. Torch is imported only by
:func:`tiny_road_checkpoint`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["textured_image", "road_frame", "tiny_road_checkpoint"]


def textured_image(shape: tuple[int, int], seed: int = 0, channels: int = 3) -> np.ndarray:
    """A smooth random texture (``uint8 H×W×channels``, or ``H×W`` for one channel), band-limited so that bilinear
    warps of it are accurate."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = shape
    small = rng.uniform(0, 255, size=(h // 8 + 2, w // 8 + 2, channels)).astype(np.float32)
    img = cv2.GaussianBlur(cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC), (0, 0), 2.0)
    img = np.clip(img, 0, 255).astype(np.uint8)
    return img.reshape(h, w, channels) if channels > 1 else img.reshape(h, w)


def road_frame(shape: tuple[int, int], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A generated frame (``uint8 H×W×3``) and its road mask (``bool H×W``): the road is a dark noisy band below a
    random horizon (45–65 % of the height), widening towards the bottom, under a bright texture."""
    rng = np.random.default_rng(seed)
    h, w = shape
    image = textured_image(shape, seed=seed).astype(np.int16) // 2 + 128
    top = int(h * rng.uniform(0.45, 0.65))
    rows, cols = np.arange(h)[:, None], np.arange(w)[None, :]
    road = (rows >= top) & (np.abs(cols - w / 2) <= (rows - top + 4) * w / h * 1.2)
    grey = rng.normal(60, 12, size=(h, w, 1)).clip(0, 255)
    return np.ascontiguousarray(np.where(road[:, :, None], grey, image).clip(0, 255).astype(np.uint8)), road


def tiny_road_checkpoint(path: Path, size: tuple[int, int], width: float) -> Path:
    """Train a Fast-SCNN of ``width`` for 60 steps on 32 :func:`road_frame` frames at ``size`` (H, W) — a few
    CPU seconds, a loss of about 0.03: masks that say something — and save it as a training checkpoint at
    ``path`` (what ``freespace export`` and ``Predictor`` read). Returns ``path``."""
    import torch

    from freespace.models import create_model

    torch.manual_seed(0)
    net = create_model("fastscnn", width=width)
    pairs = [road_frame(size, 100 + i) for i in range(32)]
    x = torch.from_numpy(np.stack([p[0] for p in pairs])).permute(0, 3, 1, 2).float() / 255
    y = torch.from_numpy(np.stack([p[1] for p in pairs])).long()
    opt = torch.optim.Adam(net.parameters(), lr=0.01)
    net.train()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny operations: a second thread only waits for the first (for ever on a busy machine)
    try:
        for step in range(60):
            idx = torch.arange(8) + 8 * (step % 4)
            loss = net.loss(net(x[idx]), y[idx])["total"]
            opt.zero_grad()
            loss.backward()
            opt.step()
    finally:
        torch.set_num_threads(threads)
    hyper = {"model": "fastscnn", "model_options": {"num_classes": 2, "width": width}, "image_size": list(size)}
    torch.save({"hyper_parameters": hyper, "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()}}, path)
    return path
