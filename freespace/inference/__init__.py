"""Running a trained network: :mod:`freespace.inference.predictor` (checkpoint or ONNX → road probabilities),
:mod:`freespace.inference.predict` (``freespace predict``, ``export``, ``kitti-submit``) and
:mod:`freespace.inference.evaluate` (``freespace evaluate``: a checkpoint on a dataset split)."""
