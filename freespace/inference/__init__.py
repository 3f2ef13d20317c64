"""Running a trained network: :mod:`freespace.inference.predictor` (checkpoint or ONNX → road probabilities)
and :mod:`freespace.inference.predict` (``freespace predict``, ``export``, ``kitti-submit``)."""
