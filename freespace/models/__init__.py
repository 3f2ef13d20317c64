"""The six segmentation networks of the paper, built by name.

>>> from freespace.models import create_model, list_models
>>> list_models()
['deeplabv3plus', 'denseaspp', 'dupsampling', 'gscnn', 'segnet', 'unet']

See :mod:`freespace.models.base` for the common interface (input in [0, 1], internal padding, train-mode
outputs, :meth:`~freespace.models.base.SegmentationModel.loss`).
"""

from freespace.models.base import IGNORE_INDEX, SegmentationModel, create_model, list_models, main_logits

__all__ = ["IGNORE_INDEX", "SegmentationModel", "create_model", "list_models", "main_logits"]
