"""freespace: collision-free space detection from stereo images.

Implements Fan et al., "Learning Collision-Free Space Detection from Stereo Images: Homography Matrix
Brings Better Data Augmentation": the road disparity model fit, the road-plane homography and the
DS-Generator (:mod:`freespace.geometry`), datasets, networks, training and evaluation.

Importing this package is cheap: it imports neither torch nor OpenCV; subpackages load what they need.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__", "adapt"]


def __getattr__(name: str):
    """``freespace.adapt`` (:func:`freespace.engine.adapt.adapt`), imported on first use: ``import freespace``
    stays free of torch."""
    if name == "adapt":  # by name: the one upward reach of layer 0 (docs/architecture.md), made on first use only
        import importlib

        return importlib.import_module("freespace.engine.adapt").adapt
    raise AttributeError(f"module 'freespace' has no attribute {name!r}")
