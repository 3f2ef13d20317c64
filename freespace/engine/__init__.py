"""Training and evaluation (PyTorch Lightning): configuration, data, the Lightning module, runs."""
