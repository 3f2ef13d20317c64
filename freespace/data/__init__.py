"""Datasets. The readers here are torch-free; training wrappers live with the engine."""
