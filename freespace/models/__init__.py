"""The six segmentation networks of the paper, built by name.

>>> from freespace.models import create_model, list_models
>>> list_models()
['contextnet', 'deeplabv3plus', 'denseaspp', 'dupsampling', 'fastscnn', 'gscnn', 'segnet', 'unet']

See :mod:`freespace.models.base` for the common interface (input in [0, 1], internal padding, train-mode
outputs, :meth:`~freespace.models.base.SegmentationModel.loss`, the ``prepare`` hook) and
:mod:`freespace.models.registry` for building by name, the preset tables and :func:`min_input_size`.
"""

# each architecture module registers itself on import
from freespace.models import contextnet, denseaspp, dupsampling, fastscnn, gscnn, segnet, smp_models  # noqa: F401
from freespace.models.base import IGNORE_INDEX, SegmentationModel, main_logits
from freespace.models.registry import create_model, list_models, min_input_size, model_options, presets

__all__ = ["IGNORE_INDEX", "SegmentationModel", "create_model", "list_models", "main_logits", "min_input_size",
           "model_options", "presets"]
