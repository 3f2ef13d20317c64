"""The protocol's vocabulary: its variants (arms), the paired gains it reports, the names of its run folders and
test sets, and a :class:`Protocol` — a study's choice among them, read from a YAML file.

Names: a *variant* is an arm of the protocol, named as in the tables (``"HA-X"``, :attr:`Variant.name`; its
run folders carry its short :attr:`Variant.tag`, ``ha``); its ``augment`` is the training configuration's
(:attr:`freespace.engine.config.TrainConfig.augment`, e.g. ``("homography",)``), which several variants may
share (X and X-long). index.json holds both: ``variant`` (the name) and ``augment`` (spelled as in
config.yaml, ``"homography"``).

A protocol file (``protocol``, :meth:`Protocol.load`) names what one study runs and reports; without one, the
method's own defaults hold (:data:`DEFAULT_VARIANTS`, :data:`GAINS`, no primary endpoint)::

    variants: [X, HA-X, X-dup, X-long]      # run when no variants are asked for (X always is)
    gains: [HA-X - X, HA-X - X-dup]         # the paired gains reported, in this order
    primary:                                # optional: the endpoint named before the run
      versus: HA-X - X-dup
      metric: f_score                       # f_score or iou
      test_set: fixed
      margin: 1.0                           # the equivalence margin, in points
    test_sets: {fixed: fixed, shifted: shifted}   # optional: NAME: DIR, as test_root takes NAME=DIR
    reference: "..."                        # optional: a sentence under the gains table (published gains)
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["Variant", "VARIANTS", "DEFAULT_VARIANTS", "GAINS", "METRICS", "GAIN_METRICS", "Primary", "Protocol",
           "TestRoots", "parse_models", "parse_variants", "parse_cell", "parse_test_roots", "run_name", "run_of"]


@dataclass(frozen=True)
class Variant:
    """A variant (one arm) of the protocol: its ``name`` in the tables (``X`` stands for the network), its
    training ``augment`` (a :attr:`~freespace.engine.config.TrainConfig.augment` value: ``()`` none), the
    ``tag`` of its run folders (``runs/<model>-<tag>-s<seed>``), ``budget``, the factor on the epoch cap
    and on the early-stopping patience (X-long: 2, as many optimiser steps as HA-X), and where the training
    labels come from: ``human`` (the dataset's), ``auto`` (the ``autolabels`` tree) or ``mix`` (the
    dataset's on :data:`MIX_HUMAN_SHARE` of the training drives, the tree's on the rest)."""

    name: str
    augment: tuple[str, ...]
    tag: str
    budget: int = 1
    labels: str = "human"

    def label(self, model: str) -> str:
        """The table row of ``model``: ``X`` replaced by the network's name (``HA-X`` → ``HA-unet``)."""
        return self.name.replace("X", model)


#: the arms, by table name
VARIANTS: dict[str, Variant] = {v.name: v for v in (
    Variant("X", (), "orig"),                              # conventional augmentation only
    Variant("HA-X", ("homography",), "ha"),                # + the DS-Generator views (the paper)
    Variant("HV-X", ("virtual",), "hv"),                   # + road-plane virtual views (no right image)
    Variant("HAV-X", ("homography", "virtual"), "hav"),    # + both
    Variant("X-dup", ("duplicate",), "dup"),               # control: HA-X's step count, the frames' own images
    Variant("X-long", (), "long", budget=2),               # control: HA-X's step count, each frame once per epoch
    Variant("X-auto", (), "auto", labels="auto"),          # labels nobody drew (freespace autolabel)
    Variant("X-mix", (), "mix", labels="mix"),             # people's labels on a fifth of the drives, autolabels after
)}
#: the share of the training drives that keep the dataset's labels in X-mix
MIX_HUMAN_SHARE = 0.2
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
_TEST_SET_NAME = re.compile(r"[a-z][a-z0-9_-]*")
_BY_TAG = {v.tag: v for v in VARIANTS.values()}
_RUN_NAME = re.compile(r"(?P<model>.+)-(?P<tag>[a-z]+)-s(?P<seed>\d+)")
#: further test sets: a folder (named ``shifted``), ``NAME=DIR`` strings, or ``{name: folder}``
TestRoots = PathLike | list[PathLike] | tuple[PathLike, ...] | dict[str, PathLike] | None
#: more seeds than this is a typo, not an experiment (each seed trains every network and variant)
MAX_SEEDS = 1000


def run_name(model: str, variant: str, seed: int) -> str:
    """The run folder of a cell: ``<model>-<tag>-s<seed>`` (``variant``: a table name)."""
    return f"{model}-{VARIANTS[variant].tag}-s{seed}"


def run_of(folder_name: str) -> tuple[str, Variant, int] | None:
    """The cell a run folder's name (``<model>-<tag>-s<seed>``) stands for: network, variant and seed; None for
    a name of another form or an unknown tag."""
    named = _RUN_NAME.fullmatch(folder_name)
    spec = _BY_TAG.get(named["tag"]) if named else None
    return (named["model"], spec, int(named["seed"])) if named and spec else None


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


def parse_variants(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """``"HA-X,X-dup"`` → the variants' table names, in the given order; ``X`` always comes first."""
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    bad = [n for n in names if n not in VARIANTS]
    if bad or not names:
        raise InvalidOptionError(f"unknown variants {bad}; choose from {', '.join(VARIANTS)} (comma-separated)")
    return tuple(["X"] + [n for n in dict.fromkeys(names) if n != "X"])  # the gains are measured against X


def parse_cell(text: str, seeds: int) -> tuple[str, str, int]:
    """``"unet,HA-X,2"`` (``only``) → ``("unet", "HA-X", 2)``: network, variant, seed.

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
    if name not in VARIANTS:
        raise InvalidOptionError(f"{param('only')}: unknown variant {name!r}; choose from {', '.join(VARIANTS)}")
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
            named = sep and _TEST_SET_NAME.fullmatch(name)  # else a folder, whatever its characters
            if sep and not named and re.fullmatch(r"\w[\w-]*", name) and not Path(text).exists():
                raise InvalidOptionError(f"{param('test_root')} {text}: test set names are lower-case letters, digits, "
                                         f"- and _ "
                                         f"(e.g. {name.lower()}={folder}); {text} is no folder either")
            pairs.append((name, folder) if named else (DEFAULT_TEST_SET, str(text)))
    roots: dict[str, Path] = {}
    for name, folder in pairs:
        if not isinstance(name, str) or not _TEST_SET_NAME.fullmatch(name) or name in RESERVED_TEST_SETS:
            raise InvalidOptionError(f"{param('test_root')}: {name!r} cannot name a test set; use lower-case letters, "
                                     f"digits, "
                                     f"- and _, and none of {', '.join(sorted(RESERVED_TEST_SETS))} (NAME=DIR)")
        if name in roots:
            raise InvalidOptionError(f"{param('test_root')}: two test sets are named {name!r}; give the others "
                                     f"NAME=DIR")
        roots[name] = Path(folder)
    return roots


# --- a study's protocol ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Primary:
    """A primary endpoint, named before a run: the gain ``versus`` (``(variant, versus)``, as in :data:`GAINS`)
    in ``metric`` points (one of :data:`GAIN_METRICS`) on the test set ``test_set``, averaged over the networks
    (one mean per seed), read against an equivalence margin of ± ``margin`` points."""

    versus: tuple[str, str]
    metric: str
    test_set: str
    margin: float


@dataclass(frozen=True)
class Protocol:
    """What one study runs and reports (see the module docstring for its file): the ``variants`` run when none
    are asked for (``X`` first), the paired ``gains`` reported (``(variant, versus)`` pairs, in order), an
    optional ``primary`` endpoint, further ``test_sets`` (``{name: folder}``; a relative folder is taken from
    the working directory, as ``test_root`` takes it) and an optional ``reference`` sentence printed under the
    gains table of results.md (e.g. the published gains to compare with). ``Protocol()`` is the method's own
    defaults: :data:`DEFAULT_VARIANTS`, :data:`GAINS`, nothing else."""

    variants: tuple[str, ...] = DEFAULT_VARIANTS
    gains: tuple[tuple[str, str], ...] = GAINS
    primary: Primary | None = None
    test_sets: dict[str, Path] = field(default_factory=dict)
    reference: str | None = None

    @classmethod
    def load(cls, path: PathLike) -> Protocol:
        """Read a protocol file (YAML, read as ``yaml.safe_load`` reads it; see the module docstring).

        Raises:
            InputFileError: no such file.
            CorruptFileError: not readable, or not YAML.
            InvalidOptionError: an unknown key, variant, metric or test set name; a gain given twice; a primary
            endpoint that is not among the gains (one line naming the file and the key).
        """
        from freespace.errors import InputFileError
        from freespace.io.codecs import load_yaml

        where = f"{param('protocol')} {path}"
        if not Path(path).is_file():
            raise InputFileError(f"{where} not found; give a study's protocol.yaml")
        data = load_yaml(path)
        if not isinstance(data, dict):
            raise InvalidOptionError(f"{where} is not a mapping of variants, gains, primary, test_sets and reference")
        unknown = sorted(set(map(str, data)) - {"variants", "gains", "primary", "test_sets", "reference"})
        if unknown:
            raise InvalidOptionError(f"{where}: unknown key {unknown[0]!r}; the keys are variants, gains, primary, "
                                     f"test_sets and reference")
        try:
            return _protocol(data)
        except InvalidOptionError as exc:
            raise InvalidOptionError(f"{where}: {exc}") from None


def _protocol(data: dict[str, Any]) -> Protocol:
    """A :class:`Protocol` of the values of a protocol file (refused in one line each)."""
    values: dict[str, Any] = {}
    if "variants" in data:
        if not isinstance(data["variants"], list) or not all(isinstance(v, str) for v in data["variants"]):
            raise InvalidOptionError("variants must be a list of variant names (e.g. [X, HA-X, X-dup])")
        values["variants"] = parse_variants(data["variants"])
    if "gains" in data:
        if not isinstance(data["gains"], list) or not data["gains"]:
            raise InvalidOptionError("gains must be a list of gains, each 'VARIANT - VERSUS' (e.g. HA-X - X)")
        gains = tuple(_gain(g) for g in data["gains"])
        if len(set(gains)) != len(gains):
            raise InvalidOptionError("gains names a gain twice; keep one")
        values["gains"] = gains
    if data.get("primary") is not None:
        values["primary"] = _primary(data["primary"], values.get("gains", GAINS))
    if data.get("test_sets") is not None:
        sets = data["test_sets"]
        if not isinstance(sets, dict) or not all(isinstance(v, str) for v in sets.values()):
            raise InvalidOptionError("test_sets must map names to folders (e.g. {shifted: shifted})")
        values["test_sets"] = parse_test_roots({str(k): v for k, v in sets.items()})
    if data.get("reference") is not None:
        if not isinstance(data["reference"], str) or "\n" in data["reference"].strip():
            raise InvalidOptionError("reference must be one line of text")
        values["reference"] = data["reference"].strip()
    return Protocol(**values)


def _gain(text: Any) -> tuple[str, str]:
    """``"HA-X - X"`` → ``("HA-X", "X")``."""
    a, sep, b = str(text).partition(" - ")
    if not isinstance(text, str) or not sep or a.strip() not in VARIANTS or b.strip() not in VARIANTS \
            or a.strip() == b.strip():
        raise InvalidOptionError(f"gain {text!r} is not 'VARIANT - VERSUS' of two variants among "
                                 f"{', '.join(VARIANTS)}")
    return a.strip(), b.strip()


def _primary(data: Any, gains: tuple[tuple[str, str], ...]) -> Primary:
    """The ``primary`` mapping → a :class:`Primary` among ``gains``."""
    keys = {"versus", "metric", "test_set", "margin"}
    if not isinstance(data, dict) or set(data) != keys:
        raise InvalidOptionError(f"primary must give {', '.join(sorted(keys))} (and nothing else)")
    versus = _gain(data["versus"])
    if versus not in gains:
        raise InvalidOptionError(f"primary's gain {data['versus']!r} is not among the gains reported")
    if data["metric"] not in GAIN_METRICS:
        raise InvalidOptionError(f"primary's metric must be one of {', '.join(GAIN_METRICS)}, got {data['metric']!r}")
    test_set = data["test_set"]
    if not isinstance(test_set, str) or not (test_set == "test" or _TEST_SET_NAME.fullmatch(test_set)):
        raise InvalidOptionError(f"primary's test_set must be test or a test set's name, got {test_set!r}")
    margin = data["margin"]
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0 < margin < float("inf"):
        raise InvalidOptionError(f"primary's margin must be a positive number of points, got {margin!r}")
    return Primary(versus, data["metric"], test_set, float(margin))
