"""The studies' own tests (``pytest studies/``; a plain ``pytest`` collects ``tests/`` only, the product's): each
study's analysis scripts, and its published tables rebuilt from its run folders byte for byte.

The studies' tests import the package and what lies in ``studies/`` only (never ``tests/`` or ``bench/``:
``tests/test_folders.py``); a study's test loads its own study's scripts by path. What they share is here:
the fixtures ``road_frame`` and ``tiny_road_checkpoint``, the studies' copy of the product tests' helpers of those
names (``tests/helpers.py``)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

#: the tables ``freespace reproduce --tables`` writes from the run folders
TABLES = ("index.json", "results.csv", "gains.csv", "results.md")


@pytest.fixture
def rebuilt_tables(tmp_path: Path) -> Callable[[Path, Path], list[str]]:
    """``check(published, protocol)``: copy the run folders of the reproduce folder ``published`` (its ``runs/``)
    into a new folder, write the tables there from them with the study's ``protocol`` file (as ``freespace
    reproduce --tables --protocol FILE`` does, without figures) and return the tables that differ from the
    published ones."""
    from freespace.experiments import Protocol, write_tables

    def check(published: Path, protocol: Path) -> list[str]:
        out = tmp_path / published.name
        shutil.copytree(published / "runs", out / "runs", symlinks=True)
        write_tables(out, figures=0, protocol=Protocol.load(protocol))
        return [name for name in TABLES if (out / name).read_bytes() != (published / name).read_bytes()]

    return check


def make_road_frame(shape: tuple[int, int], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A generated frame (``uint8 H×W×3``) and its road mask (``bool H×W``): the road is a dark noisy band below a
    random horizon (45–65 % of the height), widening towards the bottom, under a bright smooth texture."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = shape
    texture = np.random.default_rng(seed).uniform(0, 255, size=(h // 8 + 2, w // 8 + 2, 3)).astype(np.float32)
    texture = cv2.GaussianBlur(cv2.resize(texture, (w, h), interpolation=cv2.INTER_CUBIC), (0, 0), 2.0)
    image = np.clip(texture, 0, 255).astype(np.uint8).astype(np.int16) // 2 + 128
    top = int(h * rng.uniform(0.45, 0.65))
    rows, cols = np.arange(h)[:, None], np.arange(w)[None, :]
    road = (rows >= top) & (np.abs(cols - w / 2) <= (rows - top + 4) * w / h * 1.2)
    grey = rng.normal(60, 12, size=(h, w, 1)).clip(0, 255)
    return np.ascontiguousarray(np.where(road[:, :, None], grey, image).clip(0, 255).astype(np.uint8)), road


def train_road_checkpoint(path: Path, size: tuple[int, int], width: float) -> Path:
    """Train a Fast-SCNN of ``width`` for 60 steps on 32 :func:`make_road_frame` frames at ``size`` (H, W) — a few
    CPU seconds: masks that say something — and save it as a training checkpoint at ``path`` (what ``Predictor``
    reads)."""
    import torch

    from freespace.models import create_model

    torch.manual_seed(0)
    net = create_model("fastscnn", width=width)
    pairs = [make_road_frame(size, 100 + i) for i in range(32)]
    x = torch.from_numpy(np.stack([p[0] for p in pairs])).permute(0, 3, 1, 2).float() / 255
    y = torch.from_numpy(np.stack([p[1] for p in pairs])).long()
    opt = torch.optim.Adam(net.parameters(), lr=0.01)
    net.train()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny operations: a second thread only waits for the first
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


@pytest.fixture
def road_frame() -> Callable[[tuple[int, int], int], tuple[np.ndarray, np.ndarray]]:
    """:func:`make_road_frame`, for a study's test."""
    return make_road_frame


@pytest.fixture
def tiny_road_checkpoint() -> Callable[..., Path]:
    """:func:`train_road_checkpoint`, for a study's test."""
    return train_road_checkpoint
