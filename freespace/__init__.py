"""freespace: collision-free space detection from stereo images.

Implements Fan et al., "Learning Collision-Free Space Detection from Stereo Images: Homography Matrix
Brings Better Data Augmentation": the road disparity model fit, the road-plane homography and the
DS-Generator (:mod:`freespace.geometry`), datasets, networks, training and evaluation.

Importing this package is cheap: it imports neither torch nor OpenCV; subpackages load what they need.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__", "adapt", "train", "Predictor"]

#: the short entries, each imported on first use (``import freespace`` stays free of torch): name → (module, name)
_ENTRIES = {
    "train": ("freespace.engine.train", "train"),          # train a network: TrainConfig's options, run folder
    "Predictor": ("freespace.inference.predictor", "Predictor"),   # road probabilities from a checkpoint or ONNX
    "adapt": ("freespace.engine.adapt", "adapt"),          # fit a published model to unlabelled frames
}


def __getattr__(name: str):
    """``freespace.train`` (:func:`freespace.engine.train.train`), ``freespace.Predictor``
    (:class:`freespace.inference.predictor.Predictor`) and ``freespace.adapt`` (:func:`freespace.engine.adapt.adapt`),
    imported on first use: ``import freespace`` stays free of torch."""
    if name in _ENTRIES:  # by name: the upward reach of layer 0 (docs/architecture.md), made on first use only
        import importlib

        module, attr = _ENTRIES[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'freespace' has no attribute {name!r}")
