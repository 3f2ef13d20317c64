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

A study whose arms train on *other data* declares them, each with its training data (:class:`DataSource`,
:attr:`Protocol.declared`); ``reproduce`` then takes no ``dataset``/``root`` parameters::

    data:                                   # named training sources (paths: ${VAR} from the environment,
      real: {dataset: kitti-raw, root: "${RAW}", labels: "${WORK}/autolabels", splits: "${WORK}/splits",
             cache_dir: "${WORK}/sgbm-cache"}    # then relative ones from the protocol file's folder)
      rendered: {dataset: synth, root: syn}
    variants:                               # a mapping: NAME: {data, augment}; run in this order
      S: {data: rendered}
      R-auto: {data: real}
      HA-R-auto: {data: real, augment: homography}
    gains: [R-auto - S, HA-R-auto - R-auto]  # required

A declared variant's name (letters, digits, ``+``, ``-``, ``_``; none of :data:`VARIANTS`, in any case) is
literal (no ``X`` for the network); its run folders' tag is the name in lower case with ``+`` as ``_``
(:func:`variant_tag`: ``S+R-auto`` → ``s_r-auto``), unique and none of the built-in variants' tags.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["Variant", "DataSource", "DATA_KEYS", "VARIANTS", "DEFAULT_VARIANTS", "GAINS", "METRICS", "GAIN_METRICS",
           "Primary", "Protocol", "TestRoots", "parse_models", "parse_variants", "parse_cell", "parse_test_roots",
           "run_name", "run_of", "variant_tag"]


@dataclass(frozen=True)
class Variant:
    """A variant (one arm) of the protocol: its ``name`` in the tables (``X`` stands for the network), its
    training ``augment`` (a :attr:`~freespace.engine.config.TrainConfig.augment` value: ``()`` none), the
    ``tag`` of its run folders (``runs/<model>-<tag>-s<seed>``), ``budget``, the factor on the epoch cap
    and on the early-stopping patience (X-long: 2, as many optimiser steps as HA-X), and where the training
    labels come from: ``human`` (the dataset's), ``auto`` (the ``autolabels`` tree) or ``mix`` (the
    dataset's on :data:`MIX_HUMAN_SHARE` of the training drives, the tree's on the rest). ``data``: the
    training source (a :attr:`Protocol.data` name) of a variant a protocol file declares; None for the built-in
    ones, which train on ``reproduce``'s dataset."""

    name: str
    augment: tuple[str, ...]
    tag: str
    budget: int = 1
    labels: str = "human"
    data: str | None = None

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


#: a declared variant's name (a protocol file's ``variants`` mapping), and a training source's (``data``)
_VARIANT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9+_-]{0,39}")
_DATA_NAME = re.compile(r"[a-z][a-z0-9_-]{0,39}")
#: ``${NAME}`` in a training source's paths: the environment variable's value
_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")


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


def parse_variants(text: str | list[str] | tuple[str, ...],
                   variants: dict[str, Variant] | None = None) -> tuple[str, ...]:
    """``"HA-X,X-dup"`` → the variants' table names, in the given order; ``X`` always comes first. Among a
    protocol's declared ``variants`` (:attr:`Protocol.vocabulary`): the names given, in their order."""
    vocabulary = variants or VARIANTS
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
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


#: a training source's keys (``data``), and the :class:`~freespace.engine.config.TrainConfig` field each sets
DATA_KEYS = {"dataset": "dataset", "root": "root", "labels": "labels", "splits": "splits_dir", "cache_dir": "cache_dir"}


@dataclass(frozen=True)
class DataSource:
    """A named training source of a protocol file (its ``data`` mapping): the dataset layout ``dataset`` at
    ``root``; optionally ``labels``, a label tree that replaces the dataset's labels (``freespace autolabel``'s:
    :attr:`~freespace.engine.config.TrainConfig.labels`), ``splits``, a folder of ``train.txt``/``val.txt``/
    ``test.txt`` (:attr:`~freespace.engine.config.TrainConfig.splits_dir`), and ``cache_dir``, an SGBM cache,
    which only the variants with an ``augment`` get (they read disparities; the others keep the default, so that
    their settings do not depend on it).

    Paths are kept as the file spells them and resolved when cells are made (:meth:`training`; rebuilding the tables
    needs none of them): ``${NAME}`` is the environment variable's value, ``~`` the home folder, and a
    relative path is taken from ``base``, the protocol file's folder. ``file``: the protocol file, for the
    messages."""

    name: str
    dataset: str
    root: str
    labels: str | None = None
    splits: str | None = None
    cache_dir: str | None = None
    base: Path = Path(".")
    file: str = ""

    def _where(self, key: str) -> str:
        return f"{param('protocol')} {self.file}: data {self.name}: {key} {getattr(self, key)}"

    def path(self, key: str) -> Path | None:
        """The path of ``key`` (``root``, ``labels``, ``splits`` or ``cache_dir``) on this machine: ``${NAME}``
        expanded, absolute (None when the source gives none).

        Raises:
            InvalidOptionError: an environment variable it names is not set (or empty).
        """
        text = getattr(self, key)
        if text is None:
            return None
        unset = [m[1] for m in _ENV.finditer(text) if not os.environ.get(m[1])]
        if unset:
            raise InvalidOptionError(f"{self._where(key)}: the environment variable {unset[0]} is not set; "
                                     f"export {unset[0]}=DIR before the command")
        path = Path(os.path.expanduser(_ENV.sub(lambda m: os.environ[m[1]], text)))
        return path if path.is_absolute() else self.base / path

    def training(self, augment: tuple[str, ...] = ()) -> dict[str, str | None]:
        """The :class:`~freespace.engine.config.TrainConfig` values of a variant with ``augment`` that trains
        on this source: ``dataset``, ``root``, ``labels``, ``splits_dir`` and ``cache_dir`` (None: not given,
        or no ``augment``), paths resolved (:meth:`path`) and checked before any work.

        Raises:
            InvalidOptionError: an unset environment variable. InputFileError: ``root``, ``labels`` or
            ``splits`` is no folder (or ``splits`` lacks a list); ``cache_dir`` is a file. DatasetError:
            ``splits`` lists a frame twice.
        """
        from freespace.data.splits import read_splits
        from freespace.errors import FreespaceError, InputFileError

        values: dict[str, str | None] = {"dataset": self.dataset}
        for key, field_name in DATA_KEYS.items():
            if key == "dataset":
                continue
            path = self.path(key) if key != "cache_dir" or augment else None
            if path is not None and key != "cache_dir" and not path.is_dir():
                raise InputFileError(f"{self._where(key)}: no folder {path}; give the "
                                     + {"root": f"{self.dataset} dataset's folder",
                                        "labels": "label tree that `freespace autolabel` wrote",
                                        "splits": "folder of train.txt, val.txt and test.txt"}[key])
            if path is not None and key == "cache_dir" and path.is_file():
                raise InputFileError(f"{self._where(key)}: {path} is a file; give a folder for the SGBM cache")
            if path is not None and key == "splits":
                try:
                    read_splits(path)
                except FreespaceError as exc:
                    raise type(exc)(f"{self._where(key)}: {exc}") from None
            values[field_name] = None if path is None else str(path)
        return values


@dataclass(frozen=True)
class Protocol:
    """What one study runs and reports (see the module docstring for its file): the ``variants`` run when none
    are asked for (``X`` first), the paired ``gains`` reported (``(variant, versus)`` pairs, in order), an
    optional ``primary`` endpoint, further ``test_sets`` (``{name: folder}``; a relative folder is taken from
    the working directory, as ``test_root`` takes it) and an optional ``reference`` sentence printed under the
    gains table of results.md (e.g. the published gains to compare with). ``Protocol()`` is the method's own
    defaults: :data:`DEFAULT_VARIANTS`, :data:`GAINS`, nothing else.

    A protocol with ``data`` (named :class:`DataSource` s) declares its own variants, ``declared`` (by name,
    each with its ``data``; :attr:`vocabulary`), which then are all there is: ``variants`` names them in the
    file's order, and the gains and primary endpoint name them."""

    variants: tuple[str, ...] = DEFAULT_VARIANTS
    gains: tuple[tuple[str, str], ...] = GAINS
    primary: Primary | None = None
    test_sets: dict[str, Path] = field(default_factory=dict)
    reference: str | None = None
    data: dict[str, DataSource] = field(default_factory=dict)
    declared: dict[str, Variant] = field(default_factory=dict)

    @property
    def vocabulary(self) -> dict[str, Variant]:
        """The variants this protocol's names mean, in table order: its declared ones, else :data:`VARIANTS`."""
        return self.declared or VARIANTS

    @classmethod
    def load(cls, path: PathLike) -> Protocol:
        """Read a protocol file (YAML, read as ``yaml.safe_load`` reads it; see the module docstring).

        Raises:
            InputFileError: no such file.
            CorruptFileError: not readable, or not YAML.
            InvalidOptionError: an unknown key, variant, metric or test set name; a gain given twice; a primary
            endpoint that is not among the gains; with ``data``: a malformed source, a variant without data or
            of an unknown one, a name of the built-in variants, two names of one tag (one line naming the file
            and the key). The data's paths are checked when cells are made (:meth:`DataSource.training`).
        """
        from freespace.errors import InputFileError
        from freespace.io.codecs import load_yaml

        where = f"{param('protocol')} {path}"
        if not Path(path).is_file():
            raise InputFileError(f"{where} not found; give a study's protocol.yaml")
        data = load_yaml(path)
        if not isinstance(data, dict):
            raise InvalidOptionError(f"{where} is not a mapping of variants, gains, primary, test_sets, reference "
                                     f"and data")
        unknown = sorted(set(map(str, data)) - {"variants", "gains", "primary", "test_sets", "reference", "data"})
        if unknown:
            raise InvalidOptionError(f"{where}: unknown key {unknown[0]!r}; the keys are variants, gains, primary, "
                                     f"test_sets, reference and data")
        try:
            return _protocol(data, Path(path).resolve().parent, str(path))
        except InvalidOptionError as exc:
            raise InvalidOptionError(f"{where}: {exc}") from None


def _protocol(data: dict[str, Any], base: Path = Path("."), file: str = "") -> Protocol:
    """A :class:`Protocol` of the values of a protocol file in the folder ``base`` (refused in one line each)."""
    values: dict[str, Any] = {}
    vocabulary = VARIANTS
    if "data" in data:
        values["data"] = _data(data["data"], base, file)
        if not isinstance(data.get("variants"), dict):
            raise InvalidOptionError("data is the training data of the variants it declares: give variants as a "
                                     "mapping NAME: {data: SOURCE, augment: ...} (e.g. {S: {data: rendered}})")
        vocabulary = values["declared"] = _declared(data["variants"], values["data"])
        values["variants"] = tuple(vocabulary)
        if "gains" not in data:
            raise InvalidOptionError("a protocol that declares its variants names its gains (e.g. gains: "
                                     f"[{' - '.join(list(vocabulary)[1::-1]) if len(vocabulary) > 1 else 'A - B'}])")
    elif isinstance(data.get("variants"), dict):
        raise InvalidOptionError("variants given as a mapping declare their own training data: add data: {NAME: "
                                 "{dataset, root, labels, splits, cache_dir}} and name one in each variant")
    elif "variants" in data:
        if not isinstance(data["variants"], list) or not all(isinstance(v, str) for v in data["variants"]):
            raise InvalidOptionError("variants must be a list of variant names (e.g. [X, HA-X, X-dup])")
        values["variants"] = parse_variants(data["variants"])
    if "gains" in data:
        if not isinstance(data["gains"], list) or not data["gains"]:
            raise InvalidOptionError("gains must be a list of gains, each 'VARIANT - VERSUS' (e.g. HA-X - X)")
        gains = tuple(_gain(g, vocabulary) for g in data["gains"])
        if len(set(gains)) != len(gains):
            raise InvalidOptionError("gains names a gain twice; keep one")
        values["gains"] = gains
    if data.get("primary") is not None:
        values["primary"] = _primary(data["primary"], values.get("gains", GAINS), vocabulary)
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


def _gain(text: Any, variants: dict[str, Variant] = VARIANTS) -> tuple[str, str]:
    """``"HA-X - X"`` → ``("HA-X", "X")`` (two names of ``variants``)."""
    a, sep, b = str(text).partition(" - ")
    if not isinstance(text, str) or not sep or a.strip() not in variants or b.strip() not in variants \
            or a.strip() == b.strip():
        raise InvalidOptionError(f"gain {text!r} is not 'VARIANT - VERSUS' of two variants among "
                                 f"{', '.join(variants)}")
    return a.strip(), b.strip()


def _data(data: Any, base: Path, file: str) -> dict[str, DataSource]:
    """The ``data`` mapping → its :class:`DataSource` s by name (paths kept as written)."""
    from freespace.data.registry import list_datasets

    if not isinstance(data, dict) or not data:
        raise InvalidOptionError("data must map names to training sources (e.g. {rendered: {dataset: synth, root: "
                                 "syn}})")
    sources = {}
    for name, spec in data.items():
        if not isinstance(name, str) or not _DATA_NAME.fullmatch(name):
            raise InvalidOptionError(f"data name {name!r}: lower-case letters, digits, - and _ (at most 40)")
        if not isinstance(spec, dict) or not {"dataset", "root"} <= set(spec) or set(spec) - set(DATA_KEYS):
            raise InvalidOptionError(f"data {name} must give dataset and root, and optionally labels, splits and "
                                     f"cache_dir (nothing else)")
        for key, value in spec.items():
            if not isinstance(value, str) or not value.strip():
                raise InvalidOptionError(f"data {name}: {key} must be text (a name or a path), got {value!r}")
            if "$" in _ENV.sub("", value):
                raise InvalidOptionError(f"data {name}: {key} {value}: write an environment variable as ${{NAME}}, "
                                         f"and no other $")
        if spec["dataset"] not in list_datasets():
            raise InvalidOptionError(f"data {name}: unknown dataset {spec['dataset']!r}; choose one of "
                                     f"{', '.join(list_datasets())}")
        sources[name] = DataSource(name=name, base=base, file=file, **spec)
    return sources


def _declared(data: Any, sources: dict[str, DataSource]) -> dict[str, Variant]:
    """A protocol's ``variants`` mapping (``NAME: {data, augment}``) → its :class:`Variant` s, in the file's
    order, each training on one of ``sources``."""
    from freespace.engine.config import AUGMENTS, parse_augment

    if not data:
        raise InvalidOptionError("variants must declare at least one variant")
    builtin = {v.upper(): v for v in VARIANTS}
    tags = {v.tag: v.name for v in VARIANTS.values()}
    declared: dict[str, Variant] = {}
    for name, spec in data.items():
        if not isinstance(name, str) or not _VARIANT_NAME.fullmatch(name):
            raise InvalidOptionError(f"variant name {name!r}: letters, digits, +, - and _ (at most 40, not "
                                     f"starting with +, - or _)")
        if name.upper() in builtin:
            raise InvalidOptionError(f"variant {name} is (or spells) the built-in variant {builtin[name.upper()]}, "
                                     f"which trains on reproduce's own dataset; give the declared one another name")
        if not isinstance(spec, dict) or set(spec) - {"data", "augment"}:
            raise InvalidOptionError(f"variant {name} must be a mapping of data and augment (e.g. {{data: "
                                     f"{next(iter(sources))}}})")
        if spec.get("data") not in sources:
            what = f"unknown data {spec['data']!r}" if "data" in spec else "names no data"
            raise InvalidOptionError(f"variant {name}: {what}; give data: one of {', '.join(sources)}")
        try:
            augment = parse_augment(spec.get("augment", "none")) if isinstance(spec.get("augment", "none"), str) \
                else None
        except InvalidOptionError:
            augment = None
        if augment is None:
            raise InvalidOptionError(f"variant {name}: augment must be one of {', '.join(AUGMENTS)}, got "
                                     f"{spec.get('augment')!r}")
        tag = variant_tag(name)
        if tag in tags:
            raise InvalidOptionError(f"variants {tags[tag]} and {name} would share the run folders' tag {tag!r} "
                                     f"(the name in lower case, + as _); rename one")
        tags[tag] = name
        declared[name] = Variant(name, augment, tag, data=spec["data"])
    unused = [s for s in sources if all(v.data != s for v in declared.values())]
    if unused:
        raise InvalidOptionError(f"data {unused[0]} is the data of no variant; name it in one, or remove it")
    return declared


def _primary(data: Any, gains: tuple[tuple[str, str], ...], variants: dict[str, Variant] = VARIANTS) -> Primary:
    """The ``primary`` mapping → a :class:`Primary` among ``gains`` (of ``variants``)."""
    keys = {"versus", "metric", "test_set", "margin"}
    if not isinstance(data, dict) or set(data) != keys:
        raise InvalidOptionError(f"primary must give {', '.join(sorted(keys))} (and nothing else)")
    versus = _gain(data["versus"], variants)
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
