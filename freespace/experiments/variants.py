"""The protocol's vocabulary: its built-in variants (arms) and their run-folder tags, the paired gains, the
metrics, and the parsing of the names a command line gives (networks, variants, cells, test sets). A study's
choice among them is a :class:`~freespace.experiments.protocol.Protocol`."""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["Variant", "VARIANTS", "Control", "CONTROLS", "DEFAULT_VARIANTS", "GAINS", "ALL_NETWORKS",
           "PAPER_NETWORKS", "GAIN_METRICS", "METRICS", "METRIC_NAMES", "DEFAULT_TEST_SET",
           "RESERVED_TEST_SETS", "TEST_SET_NAME", "MAX_SEEDS", "TestRoots", "variant_tag", "run_name", "run_of",
           "parse_models", "parse_variants", "parse_cell", "parse_test_roots"]

@dataclass(frozen=True)
class Variant:
    """A variant (one arm) of the protocol: its ``name`` in the tables (``X`` stands for the network), its
    training ``augment`` (a :attr:`~freespace.engine.config.TrainConfig.augment` value: ``()`` none), the
    ``tag`` of its run folders (``runs/<model>-<tag>-s<seed>``), ``budget``, the factor on the epoch cap
    and on the early-stopping patience (X-long: 2, as many optimiser steps as HA-X), and where the training
    labels come from: ``human`` (the dataset's), ``auto`` (the ``autolabels`` tree) or ``mix`` (the
    dataset's on a share of the training drives, the tree's on the rest). ``controls``: the study controls the
    variant reads from the protocol (:data:`CONTROLS`; X-mix: that share). ``data``: the
    training source (a :attr:`Protocol.data` name) of a variant a protocol file declares; None for the built-in
    ones, which train on ``reproduce``'s dataset. ``samples``: the per-sample augmentations a declared variant
    adds to the conventional one (``flip``, ``photometric``: :class:`~freespace.engine.config.TrainConfig`'s
    switches of those names)."""

    name: str
    augment: tuple[str, ...]
    tag: str
    budget: int = 1
    labels: str = "human"
    data: str | None = None
    samples: tuple[str, ...] = ()
    controls: tuple[str, ...] = ()

    def label(self, model: str) -> str:
        """The table row of ``model``: ``X`` replaced by the network's name (``HA-X`` → ``HA-unet``); a declared
        variant's name as it is."""
        return self.name if self.data is not None else self.name.replace("X", model)


#: the arms, by table name
VARIANTS: dict[str, Variant] = {v.name: v for v in (
    Variant("X", (), "orig"),                              # conventional augmentation only
    Variant("HA-X", ("homography",), "ha"),                # + the DS-Generator views (the paper)
    Variant("HV-X", ("virtual",), "hv"),                   # + road-plane virtual views (no right image)
    Variant("HAV-X", ("homography", "virtual"), "hav"),    # + both
    Variant("X-dup", ("duplicate",), "dup"),               # control: HA-X's step count, the frames' own images
    Variant("X-long", (), "long", budget=2),               # control: HA-X's step count, each frame once per epoch
    Variant("X-auto", (), "auto", labels="auto"),          # labels nobody drew (freespace autolabel)
    Variant("X-mix", (), "mix", labels="mix",              # people's labels on a share of the drives, autolabels after
            controls=("mix_human_share",)),
)}


@dataclass(frozen=True)
class Control:
    """A study control: a value a built-in variant needs that the method leaves to the study, which declares it
    in its protocol file (``controls: {name: value}``; :attr:`~freespace.experiments.protocol.Protocol.controls`).
    ``field``: the :class:`~freespace.engine.config.TrainConfig` field it sets in the variant's cells; the value
    lies strictly between ``low`` and ``high``; ``help``: what it is, for the messages."""

    name: str
    field: str
    low: float
    high: float
    help: str


#: the study controls, by name (the paper defines none of them: no defaults)
CONTROLS: dict[str, Control] = {c.name: c for c in (
    Control("mix_human_share", "human_share", 0.0, 1.0, "X-mix: the share of the training drives that keep the "
            "dataset's labels (the label tree's on the rest)"),
)}
DEFAULT_VARIANTS = ("X", "HA-X", "X-dup")
#: the paired gains reported (variant, versus), when both were run (X-dup − X-long: the second draw of the
#: conventional augmentation at equal optimiser steps)
GAINS = (("HA-X", "X"), ("HA-X", "X-dup"), ("HA-X", "X-long"), ("X-dup", "X"), ("X-long", "X"), ("X-dup", "X-long"),
         ("HV-X", "X"), ("HAV-X", "X"), ("X-auto", "X"), ("X-mix", "X"), ("X-mix", "X-auto"))
#: the ``network`` of the gains averaged over networks
ALL_NETWORKS = "all"
#: the paper's six networks: what ``models="all"`` trains (networks registered later, e.g. ``fastscnn``, by name)
PAPER_NETWORKS = ("deeplabv3plus", "denseaspp", "dupsampling", "gscnn", "segnet", "unet")
GAIN_METRICS = ("f_score", "iou")
METRICS = ("accuracy", "precision", "recall", "f_score", "iou")
#: the metrics' names in results.md and the figures
METRIC_NAMES = {"accuracy": "Accuracy", "precision": "Precision", "recall": "Recall", "f_score": "F-score",
                "iou": "IoU"}
#: the name of a further test set (``test_root``) given without one
DEFAULT_TEST_SET = "shifted"
#: names a further test set cannot take: the test split's, and the run folder's own entries
RESERVED_TEST_SETS = frozenset({"train", "val", "test", "metrics", "config", "splits", "generated", "checkpoints",
                                "tensorboard"})
TEST_SET_NAME = re.compile(r"[a-z][a-z0-9_-]*")
_BY_TAG = {v.tag: v for v in VARIANTS.values()}
_RUN_NAME = re.compile(r"(?P<model>.+)-(?P<tag>[a-z]+)-s(?P<seed>\d+)")
#: further test sets: a folder (named ``shifted``), ``NAME=DIR`` strings, or ``{name: folder}``
TestRoots = PathLike | list[PathLike] | tuple[PathLike, ...] | dict[str, PathLike] | None
#: more seeds than this is a typo, not an experiment (each seed trains every network and variant)
MAX_SEEDS = 1000




def variant_tag(name: str) -> str:
    """The run folders' tag of a declared variant: ``name`` in lower case, ``+`` as ``_`` (``S+R-auto`` →
    ``s_r-auto``; letters, digits, ``-`` and ``_``: safe in a folder name)."""
    return name.lower().replace("+", "_")


def run_name(model: str, variant: str, seed: int, variants: dict[str, Variant] | None = None) -> str:
    """The run folder of a cell: ``<model>-<tag>-s<seed>`` (``variant``: a table name of ``variants``, by
    default :data:`VARIANTS`; :attr:`Protocol.vocabulary`)."""
    return f"{model}-{(variants or VARIANTS)[variant].tag}-s{seed}"


def run_of(folder_name: str, variants: dict[str, Variant] | None = None) -> tuple[str, Variant, int] | None:
    """The cell a run folder's name (``<model>-<tag>-s<seed>``) stands for: network, variant (of ``variants``,
    by default :data:`VARIANTS`) and seed; None for a name of another form or an unknown tag. A declared
    variant's tag may hold ``-``: the longest tag that leaves a network's name wins (``unet-ha-r-auto-s0`` is
    HA-R-auto's, not R-auto's of a network ``unet-ha``)."""
    if variants is None or variants is VARIANTS:
        named = _RUN_NAME.fullmatch(folder_name)
        spec = _BY_TAG.get(named["tag"]) if named else None
        return (named["model"], spec, int(named["seed"])) if named and spec else None
    named = re.fullmatch(r"(?P<rest>.+)-s(?P<seed>\d+)", folder_name)
    if named is None:
        return None
    for spec in sorted(variants.values(), key=lambda v: -len(v.tag)):
        model = named["rest"][: -len(spec.tag) - 1]
        if model and named["rest"] == f"{model}-{spec.tag}":
            return model, spec, int(named["seed"])
    return None


def parse_models(text: str | list[str] | tuple[str, ...] | None) -> list[str]:
    """``"unet,segnet"`` (``models``) → the networks, in the given order; ``"all"`` or None → the paper's six
    (:data:`PAPER_NETWORKS`).

    Raises:
        InvalidOptionError: an unknown network, or none.
    """
    from freespace.models import list_models

    if text is None or text == "all":
        return list(PAPER_NETWORKS)
    names = list(dict.fromkeys(n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()))
    unknown = [n for n in names if n not in list_models()]
    if unknown or not names:
        raise InvalidOptionError(f"unknown models {unknown}; choose from {', '.join(list_models())} or all")
    return names


def _variant_name(name: str, vocabulary: Iterable[str]) -> str:
    """``name`` as the vocabulary spells it when it differs only in case from exactly one entry (run folders
    are lower case: ``contextnet-ha-r-auto-s0`` is variant ``HA-R-auto``); else ``name`` unchanged."""
    if name in vocabulary:
        return name
    same = [v for v in vocabulary if v.lower() == name.lower()]
    return same[0] if len(same) == 1 else name


def parse_variants(text: str | list[str] | tuple[str, ...],
                   variants: dict[str, Variant] | None = None) -> tuple[str, ...]:
    """``"HA-X,X-dup"`` → the variants' table names, in the given order; ``X`` always comes first. Among a
    protocol's declared ``variants`` (:attr:`Protocol.vocabulary`): the names given, in their order."""
    vocabulary = variants or VARIANTS
    names = [_variant_name(n.strip(), vocabulary) for n in (text.split(",") if isinstance(text, str) else text)
             if n.strip()]
    bad = [n for n in names if n not in vocabulary]
    if bad or not names:
        raise InvalidOptionError(f"unknown variants {bad}; choose from {', '.join(vocabulary)} (comma-separated)")
    if vocabulary is not VARIANTS:
        return tuple(dict.fromkeys(names))
    return tuple(["X"] + [n for n in dict.fromkeys(names) if n != "X"])  # the gains are measured against X


def parse_cell(text: str, seeds: int, variants: dict[str, Variant] | None = None) -> tuple[str, str, int]:
    """``"unet,HA-X,2"`` (``only``) → ``("unet", "HA-X", 2)``: network, variant (of ``variants``, by default
    :data:`VARIANTS`), seed.

    Raises:
        InvalidOptionError: not three comma-separated fields, an unknown network or variant, or a seed
        outside ``0 … seeds − 1``.
    """
    from freespace.models import list_models

    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 3:
        raise InvalidOptionError(f"{param('only')} must be NETWORK,VARIANT,SEED (e.g. unet,HA-X,0), got {text!r}")
    model, name, seed_text = parts
    if model not in list_models():
        raise InvalidOptionError(f"{param('only')}: unknown network {model!r}; choose from {', '.join(list_models())}")
    vocabulary = variants or VARIANTS
    name = _variant_name(name, vocabulary)
    if name not in vocabulary:
        raise InvalidOptionError(f"{param('only')}: unknown variant {name!r}; choose from {', '.join(vocabulary)}")
    if not seed_text.isdigit() or not 0 <= int(seed_text) < seeds:
        raise InvalidOptionError(f"{param('only')}: the seed must be an integer in 0…{seeds - 1} ({param('seeds')} "
                                 f"{seeds}), "
                                 f"got {seed_text!r}")
    return model, name, int(seed_text)


def parse_test_roots(test_root: TestRoots) -> dict[str, Path]:
    """``test_root`` values → ``{name: folder}``: ``DIR`` is named ``shifted``, ``NAME=DIR`` ``NAME``
    (lower-case letters, digits, ``-`` and ``_``; not ``test``, the test split's). A dict is taken as it is.

    Raises:
        InvalidOptionError: a bad or repeated name.
    """
    if test_root is None:
        return {}
    if isinstance(test_root, dict):
        pairs = list(test_root.items())
    else:
        pairs = []
        for text in [test_root] if isinstance(test_root, (str, Path)) else test_root:
            name, sep, folder = str(text).partition("=")
            named = sep and TEST_SET_NAME.fullmatch(name)  # else a folder, whatever its characters
            if sep and not named and re.fullmatch(r"\w[\w-]*", name) and not Path(text).exists():
                raise InvalidOptionError(f"{param('test_root')} {text}: test set names are lower-case letters, digits, "
                                         f"- and _ "
                                         f"(e.g. {name.lower()}={folder}); {text} is no folder either")
            pairs.append((name, folder) if named else (DEFAULT_TEST_SET, str(text)))
    roots: dict[str, Path] = {}
    for name, folder in pairs:
        if not isinstance(name, str) or not TEST_SET_NAME.fullmatch(name) or name in RESERVED_TEST_SETS:
            raise InvalidOptionError(f"{param('test_root')}: {name!r} cannot name a test set; use lower-case letters, "
                                     f"digits, "
                                     f"- and _, and none of {', '.join(sorted(RESERVED_TEST_SETS))} (NAME=DIR)")
        if name in roots:
            raise InvalidOptionError(f"{param('test_root')}: two test sets are named {name!r}; give the others "
                                     f"NAME=DIR")
        roots[name] = Path(folder)
    return roots
