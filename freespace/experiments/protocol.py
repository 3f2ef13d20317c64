"""A study's :class:`Protocol`, read from a YAML file: its choice among the variants and gains of
:mod:`~freespace.experiments.variants` (the vocabulary: variants, gains, run-folder names, the parsing of
names), or variants of its own with their own training data (:class:`DataSource`).

Names: a *variant* is an arm of the protocol, named as in the tables (``"HA-X"``,
:attr:`~freespace.experiments.variants.Variant.name`; its run folders carry its short
:attr:`~freespace.experiments.variants.Variant.tag`, ``ha``); its ``augment`` is the training configuration's
(:attr:`freespace.engine.config.TrainConfig.augment`, e.g. ``("homography",)``), which several variants may
share (X and X-long). index.json holds both: ``variant`` (the name) and ``augment`` (spelled as in
config.yaml, ``"homography"``).

A protocol file (``protocol``, :meth:`Protocol.load`) names what one study runs and reports; without one, the
method's own defaults hold (:data:`~freespace.experiments.variants.DEFAULT_VARIANTS`,
:data:`~freespace.experiments.variants.GAINS`, no primary endpoint)::

    variants: [X, HA-X, X-dup, X-long]      # run when no variants are asked for (X always is)
    gains: [HA-X - X, HA-X - X-dup]         # the paired gains reported, in this order
    primary:                                # optional: the endpoint named before the run
      versus: HA-X - X-dup
      metric: f_score                       # f_score or iou
      test_set: fixed
      margin: 1.0                           # the equivalence margin, in points
    test_sets: {fixed: fixed, shifted: shifted}   # optional: NAME: DIR, as test_root takes NAME=DIR
    reference: "..."                        # optional: a sentence under the gains table (published gains)
    controls: {mix_human_share: 0.2}        # the study controls its variants read (CONTROLS; X-mix: this one)

A study control (:data:`~freespace.experiments.variants.CONTROLS`) is a value a built-in variant needs that the
paper does not fix, so the study that runs the variant declares it: X-mix's ``mix_human_share``, the share of
the training drives that keep the dataset's labels. The library has no default for it: running X-mix without
a protocol that declares it is refused before any cell trains, and a protocol that declares a control none of
its variants or gains reads is refused.

A study whose arms train on *other data* declares them, each with its training data (:class:`DataSource`,
:attr:`Protocol.declared`); ``reproduce`` then takes no ``dataset``/``root`` parameters::

    data:                                   # named training sources (paths: ${VAR} from the environment,
      real: {dataset: kitti-raw, root: "${RAW}", labels: "${WORK}/autolabels", splits: "${WORK}/splits",
             cache_dir: "${WORK}/sgbm-cache"}    # then relative ones from the protocol file's folder)
      rendered: {dataset: kitti, root: syn}   # the renderer's output: a KITTI road tree
    variants:                               # a mapping: NAME: {data, augment, flip, photometric}; in this order
      S: {data: rendered}
      R-auto: {data: real}
      HA-R-auto: {data: real, augment: homography}
      R-auto-fp: {data: real, flip: true, photometric: true}   # the TrainConfig switches of those names
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
from freespace.experiments.variants import (
    CONTROLS,
    DEFAULT_VARIANTS,
    GAIN_METRICS,
    GAINS,
    TEST_SET_NAME,
    VARIANTS,
    Variant,
    parse_test_roots,
    parse_variants,
    variant_tag,
)
from freespace.io.files import PathLike, missing_input

__all__ = ["DataSource", "DATA_KEYS", "Primary", "Protocol"]

#: a declared variant's name (a protocol file's ``variants`` mapping), and a training source's (``data``)
_VARIANT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9+_-]{0,39}")
_DATA_NAME = re.compile(r"[a-z][a-z0-9_-]{0,39}")
#: the per-sample augmentations a declared variant may switch on (TrainConfig's switches)
_SAMPLES = ("flip", "photometric")
#: a protocol file's keys
_KEYS = ("variants", "gains", "primary", "test_sets", "reference", "data", "controls")
#: ``${NAME}`` in a training source's paths: the environment variable's value
_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")


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
    base: Path = Path(".")
    file: str = ""
    labels: str | None = None
    splits: str | None = None
    cache_dir: str | None = None

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
    controls: dict[str, float] = field(default_factory=dict)

    @property
    def vocabulary(self) -> dict[str, Variant]:
        """The variants this protocol's names mean, in table order: its declared ones, else :data:`VARIANTS`."""
        return self.declared or VARIANTS

    def control_values(self, variant: str) -> dict[str, float]:
        """The :class:`~freespace.engine.config.TrainConfig` values the study controls of ``variant`` set
        (X-mix: ``{"human_share": mix_human_share}``), from :attr:`controls`.

        Raises:
            InvalidOptionError: the protocol does not declare a control the variant reads (named, with how).
        """
        values = {}
        for name in self.vocabulary[variant].controls:
            if name not in self.controls:
                raise InvalidOptionError(f"{variant} reads the study control {name} ({CONTROLS[name].help}), which "
                                         f"the study declares: give {param('protocol')} a file with controls: "
                                         f"{{{name}: VALUE}}")
            values[CONTROLS[name].field] = self.controls[name]
        return values

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
        from freespace.io.codecs import load_yaml

        where = f"{param('protocol')} {path}"
        if not Path(path).is_file():
            raise missing_input(path, param("protocol"), hint="give a study's protocol.yaml")
        data = load_yaml(path)
        if not isinstance(data, dict):
            raise InvalidOptionError(f"{where} is not a mapping of {', '.join(_KEYS[:-1])} and {_KEYS[-1]}")
        unknown = sorted(set(map(str, data)) - set(_KEYS))
        if unknown:
            raise InvalidOptionError(f"{where}: unknown key {unknown[0]!r}; the keys are {', '.join(_KEYS[:-1])} and "
                                     f"{_KEYS[-1]}")
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
    if data.get("controls") is not None:
        named = {*values.get("variants", DEFAULT_VARIANTS), *(v for g in values.get("gains", GAINS) for v in g)}
        values["controls"] = _controls(data["controls"], [vocabulary[v] for v in vocabulary if v in named])
    return Protocol(**values)


def _controls(data: Any, variants: list[Variant]) -> dict[str, float]:
    """The ``controls`` mapping → ``{name: value}``, each a known control (:data:`CONTROLS`) that one of
    ``variants`` (the protocol's variants and those of its gains) reads, with a value within its bounds."""
    if not isinstance(data, dict):
        raise InvalidOptionError(f"controls must map study controls to values (e.g. {{mix_human_share: 0.2}}); the "
                                 f"controls are {', '.join(CONTROLS)}")
    controls = {}
    for name, value in data.items():
        if name not in CONTROLS:
            raise InvalidOptionError(f"controls: unknown control {name!r}; the controls are "
                                     + "; ".join(f"{c.name} ({c.help})" for c in CONTROLS.values()))
        control = CONTROLS[name]
        readers = [v.name for v in VARIANTS.values() if name in v.controls]
        if not any(name in v.controls for v in variants):
            raise InvalidOptionError(f"controls: {name} is read by {', '.join(readers)}, which this protocol neither "
                                     f"runs nor reports; name it in variants or gains, or leave {name} out")
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not control.low < value < control.high:
            raise InvalidOptionError(f"controls: {name} must be a number strictly between {control.low:g} and "
                                     f"{control.high:g} ({control.help}), got {value!r}")
        controls[name] = float(value)
    return controls


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
        raise InvalidOptionError("data must map names to training sources (e.g. {rendered: {dataset: kitti, root: "
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
        if spec["dataset"] not in list_datasets(aliases=True):  # an earlier name too (studies' files keep theirs)
            raise InvalidOptionError(f"data {name}: unknown dataset {spec['dataset']!r}; choose one of "
                                     f"{', '.join(list_datasets(aliases=False))}")
        sources[name] = DataSource(name=name, base=base, file=file, **spec)
    return sources


def _declared(data: Any, sources: dict[str, DataSource]) -> dict[str, Variant]:
    """A protocol's ``variants`` mapping (``NAME: {data, augment, flip, photometric}``) → its :class:`Variant` s,
    in the file's order, each training on one of ``sources``."""
    from freespace.engine.option_values import AUGMENTS, parse_augment

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
        if not isinstance(spec, dict) or set(spec) - {"data", "augment", *_SAMPLES}:
            raise InvalidOptionError(f"variant {name} must be a mapping of data, augment, flip and photometric (e.g. "
                                     f"{{data: {next(iter(sources))}}})")
        wrong = next((k for k in _SAMPLES if not isinstance(spec.get(k, False), bool)), None)
        if wrong:
            raise InvalidOptionError(f"variant {name}: {wrong} must be true or false, got {spec[wrong]!r}")
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
        declared[name] = Variant(name, augment, tag, data=spec["data"],
                                 samples=tuple(k for k in _SAMPLES if spec.get(k)))
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
    if not isinstance(test_set, str) or not (test_set == "test" or TEST_SET_NAME.fullmatch(test_set)):
        raise InvalidOptionError(f"primary's test_set must be test or a test set's name, got {test_set!r}")
    margin = data["margin"]
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0 < margin < float("inf"):
        raise InvalidOptionError(f"primary's margin must be a positive number of points, got {margin!r}")
    return Primary(versus, data["metric"], test_set, float(margin))
