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

The training sources and declared variants are read by :mod:`freespace.experiments.data_source` (its
:class:`DataSource` and ``DATA_KEYS`` are importable from here too).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from freespace.errors import InvalidOptionError, param
from freespace.experiments.data_source import DATA_KEYS, DataSource, data_sources, declared_variants
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
)
from freespace.io.files import PathLike, missing_input

__all__ = ["DataSource", "DATA_KEYS", "Primary", "Protocol"]

#: a protocol file's keys
_KEYS = ("variants", "gains", "primary", "test_sets", "reference", "data", "controls")


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
        values["data"] = data_sources(data["data"], base, file)
        if not isinstance(data.get("variants"), dict):
            raise InvalidOptionError("data is the training data of the variants it declares: give variants as a "
                                     "mapping NAME: {data: SOURCE, augment: ...} (e.g. {S: {data: rendered}})")
        vocabulary = values["declared"] = declared_variants(data["variants"], values["data"])
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
