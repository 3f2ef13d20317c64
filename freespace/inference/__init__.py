"""Running a trained network: :mod:`freespace.inference.predictor` (checkpoint or ONNX → road probabilities),
:mod:`freespace.inference.predict` (``freespace predict``), :mod:`freespace.inference.export` (``export``),
:mod:`freespace.inference.submission` (``kitti-submit``) and :mod:`freespace.inference.evaluate`
(``freespace evaluate``: a checkpoint on a dataset split)."""
