"""freespace: drivable road (collision-free space) from stereo images — road model, DS-Generator, training, deployment.

The command line parses options, calls the library and reports.

Each command's options are declared beside its handler (``_<command>_parser``); the options of ``train``
and ``reproduce`` are generated from :class:`~freespace.engine.config.TrainConfig`'s fields (the flag of a
field is ``--name-with-dashes``, or the one :data:`CONFIG_FLAGS` names). Only the parser of the
command that runs is filled in, and heavy modules are imported inside each command, so that ``freespace
generate`` starts fast and never imports torch. Every :class:`~freespace.errors.FreespaceError` ends the
command with a one-line message on stderr and exit code 2; a dataset run with failed frames exits with 1.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from freespace import __version__
from freespace.errors import MAX_SEED, FreespaceError, InvalidOptionError, Terminated, param
from freespace.limits import (
    MAX_BASELINE_M,
    MAX_BATCH_SIZE,
    MAX_CURB_HEIGHT_M,
    MAX_DISPARITY_PX,
    MAX_EPOCHS,
    MAX_FRAME_COUNT,
    MAX_INLIER_THRESHOLD_PX,
    MAX_LIDAR_FILL_PX,
    MAX_NOISE_PX,
    MAX_POSE,
    MIN_BASELINE_M,
    WORKERS_PER_CORE,
    bounded_float,
    bounded_int,
    bounded_triple,
    max_workers,
)

# --- options shared by several commands ----------------------------------------------------------------

#: worker processes (generate, autolabel, synth): at most a few per CPU core of this machine
_WORKERS = bounded_int(1, max_workers, why=f"{WORKERS_PER_CORE} per CPU core")
_SEED = bounded_int(0, MAX_SEED)


class _Parser(argparse.ArgumentParser):
    """argparse, except that an argument starting with a minus and a digit, ``inf`` or ``nan`` is a value,
    never an option: ``--shift -1,0,0``, ``--rotate -2,0,0`` and ``--pitches -5,5`` need no ``=`` form (no
    option of this command starts that way). Sub-command parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|inf|nan)", re.IGNORECASE)

    def error(self, message: str) -> Any:  # argparse: NoReturn
        """argparse's own mistakes (a missing required option, an unknown choice or command) end in one line
        like every other user mistake, pointing to the command's help instead of printing the usage."""
        raise InvalidOptionError(f"{message}; see `{self.prog} --help`")

    def _get_value(self, action: argparse.Action, arg_string: str) -> Any:
        """An empty value ('' or blanks: a path that would be the current folder) and a value of an option of this
        module's types (:class:`~freespace.limits.Bounded`: out of its bounds, or no number) are refused in one
        line naming the option (argparse's own message comes with the usage)."""
        if action.option_strings and isinstance(arg_string, str) and not arg_string.strip():  # '' = the current folder
            raise InvalidOptionError(f"{param(action.dest)} is empty; give it a value"
                                     + ("" if action.required else ", or leave it out"))
        if action.type is not None and not isinstance(action.type, type):  # Bounded, _range: one line
            try:
                return action.type(arg_string)
            except (InvalidOptionError, argparse.ArgumentTypeError) as exc:
                raise InvalidOptionError(f"{param(action.dest)} {exc}") from None
        return super()._get_value(action, arg_string)


def _add_dataset_root(p: argparse.ArgumentParser | argparse._ArgumentGroup, required: bool = True,
                      split: bool = True) -> None:
    """``--dataset``, ``--root`` and (optionally) ``--split``, shared by every command that reads a dataset. A
    layout's earlier name (``synth``, ``kitti_road``, ``kitti_raw``, ``syn-stereo``) is read as its name."""
    from freespace.data.registry import canonical_dataset, list_datasets

    p.add_argument("--dataset", choices=list_datasets(aliases=False), required=required, type=canonical_dataset,
                   help="layout: kitti (KITTI road, and the renderer's output: `freespace synth` writes a KITTI road "
                        "tree), kitti-raw (KITTI raw drives), synthia, carla (CARLA exports, e.g. SYN-Stereo), generic")
    p.add_argument("--root", metavar="DIR", required=required, help="dataset folder")
    if split:
        p.add_argument("--split", help="the dataset's on-disk split, a folder it ships (KITTI road: training or "
                                       "testing; default: the first); not train/val/test, which are subsets")


def _open_dataset(args: argparse.Namespace, needs_right: str | None = None):  # -> StereoRoadDataset (lazy import)
    """The dataset the options name (:func:`~freespace.data.options.open_dataset`)."""
    from freespace.data.options import open_dataset

    return open_dataset(args.dataset, args.root, args.split, disparity_source=args.disparity_source,
                        cache_dir=args.cache_dir, max_disparity=args.max_disparity, disparity_dir=args.disparity_dir,
                        lidar_densify=args.lidar_densify, needs_right=needs_right)


@dataclass(frozen=True)
class _Mode:
    """One of the ways a command runs that share its parser (``generate``: one pair, a dataset or a virtual
    view): the options (argparse ``dest``) that belong to it, those it needs, and how messages call it."""

    what: str
    options: frozenset[str]
    required: tuple[str, ...] = ()
    hint: str = ""


def _check_mode(parser: argparse.ArgumentParser, args: argparse.Namespace, modes: Mapping[str, _Mode],
                chosen: str) -> None:
    """Refuse, in one line, the options of the other ``modes`` given (not at their default) to the
    ``chosen`` one, then the options ``chosen`` needs and lacks. An option of no mode belongs to all."""
    mode = modes[chosen]
    others = set().union(*(m.options for m in modes.values())) - mode.options
    flags = _flags(parser, [])
    given = [a.dest for a in parser._actions if a.dest in others and a.option_strings
             and getattr(args, a.dest) != a.default]
    if given:
        owners = " or ".join(m.what for m in modes.values() if m.options & set(given))
        raise InvalidOptionError(f"{', '.join(flags[d] for d in given)} {'is' if len(given) == 1 else 'are'} for "
                                 f"{owners}, not for {mode.what}; leave {'it' if len(given) == 1 else 'them'} out")
    missing = [flags[d] for d in mode.required if getattr(args, d) in (None, False)]
    if missing:
        raise InvalidOptionError(f"{mode.what} needs {', '.join(missing)}{mode.hint} (see --help)")


def _refuse_folders(args: argparse.Namespace, names: Sequence[str]) -> None:
    """Refuse a folder given to an option that reads one file (``names``: argparse ``dest``), first: later checks
    would blame something else (an output inside that "input folder")."""
    from freespace.errors import InputFileError

    for name in names:
        value = getattr(args, name, None)
        if value is not None and os.path.isdir(value):
            raise InputFileError(f"{param(name)} {value} is a folder; give a file")


def _run_dataset(args: argparse.Namespace, run: Callable[..., dict[str, Any]], options: Any, done: str,
                 needs_right: str | None = None) -> int:
    """The dataset mode of ``generate`` and ``autolabel``: ``run`` (``generate_dataset``, ``autolabel_dataset``)
    over the dataset the options name, then one line of counts (``summary[done]`` frames made) and one per
    failed frame; exit code 1 when a frame failed."""
    from freespace.datagen.runner import run_report
    from freespace.runtime.shard import parse_shard

    shard = parse_shard(args.shard) if args.shard is not None else None
    summary = run(_open_dataset(args, needs_right), args.out, workers=args.workers, options=options,
                  overwrite=args.overwrite, shard=shard)
    flags = _flags(args.parser, [])  # this run's failures name flags, not parameters
    print(run_report(summary, done, args.out, args.shard if shard else None, lambda n: flags.get(n, n)))
    return 1 if summary["failed"] else 0


# --- generate ------------------------------------------------------------------------------------------


def _generate_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.disparity import DISPARITY_SOURCES
    from freespace.geometry import SGBM_MAX_DISPARITY

    one = p.add_argument_group("one pair")
    one.add_argument("--reference", metavar="L.png", help="reference (left) image")
    one.add_argument("--target", metavar="R.png", help="target (right) image")
    one.add_argument("--road-mask", metavar="GT.png",
                     help="road label of the reference image: KITTI colours or single-channel (non-zero = road)")
    one.add_argument("--disparity", metavar="D", help="left disparity (KITTI uint16 .png, .npy, .pfm); "
                                                      "default: computed with SGBM")
    one.add_argument("--model-json", metavar="M.json", help="also write the fitted model as JSON")
    virt = p.add_argument_group("a virtual view (--virtual): the reference image from another camera pose, no "
                                "right image; camera frame x right, y down, z forward (metres)")
    virt.add_argument("--virtual", action="store_true", help="warp --reference and --road-mask to the pose "
                      "--shift/--rotate through the road plane (from --disparity's fit, else Tr_cam_to_road)")
    virt.add_argument("--calib", metavar="CALIB.txt",
                      help="KITTI calibration (P2, P3; Tr_cam_to_road without --disparity)")
    virt.add_argument("--shift", metavar="DX,DY,DZ", type=bounded_triple(MAX_POSE),
                      help="camera centre move in metres (+x right, +y down; default 0,0,0)")
    virt.add_argument("--rotate", metavar="ROLL,PITCH,YAW", type=bounded_triple(MAX_POSE),
                      help="degrees about z, x, y, R = R_yaw·R_pitch·R_roll; "
                      "positive pitch looks down, positive yaw left (default 0,0,0)")
    virt.add_argument("--label-out", metavar="VL.png", help="the view's label, KITTI colours (don't care black)")
    g = p.add_argument_group("dataset")
    _add_dataset_root(g, required=False)
    g.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of <frame>.png|.npy|.pfm disparities")
    g.add_argument("--disparity-source", dest="disparity_source", choices=DISPARITY_SOURCES, default="auto",
                   help="auto: file, else depth + camera, else cached SGBM (default); depth: depth maps only "
                        "(KITTI: depth_u16/); lidar: Velodyne scans only (KITTI: velodyne/<frame>.bin)")
    g.add_argument("--lidar-densify", type=bounded_float(0, MAX_LIDAR_FILL_PX), metavar="PX",
                   help="--disparity-source lidar: fill holes within PX pixels of a point with its value "
                        "(default: keep the sparse map, which is all the road fit needs)")
    g.add_argument("--cache-dir", metavar="DIR", help="SGBM disparity cache (default ~/.cache/freespace/sgbm)")
    g.add_argument("--labels", metavar="TREE", help="the road labels to fit from a label tree (`freespace autolabel`'s "
                                                    "output: TREE/<frame>.png) instead of the dataset's own, for a "
                                                    "dataset without labels (KITTI raw); frames without one are "
                                                    "skipped")
    g.add_argument("--shard", metavar="K/N", help="only the K-th of N disjoint parts of the frames (K from 1, "
                                                  "e.g. ${SLURM_ARRAY_TASK_ID}/N); totals go to "
                                                  "summary.shard-K-of-N.json and report.shard-K-of-N.csv")
    p.add_argument("--workers", type=_WORKERS, default=1, help="processes, for --dataset (default 1)")
    p.add_argument("--out", required=True, help="output image (one pair) or folder (dataset)")
    p.add_argument("--overwrite", action="store_true",
                   help="--dataset: replace what an earlier run with other settings generated in --out")
    g = p.add_argument_group("road fit")
    g.add_argument("--inlier-threshold", type=bounded_float(0, MAX_INLIER_THRESHOLD_PX, low_open=True), default=1.0,
                   metavar="PX",
                   help="disparity residual (pixels) above which a road pixel is an outlier (default 1.0)")
    g.add_argument("--no-robust", dest="robust", action="store_false",
                   help="plain least squares over all valid road pixels (no outlier rejection)")
    g.add_argument("--max-disparity", type=bounded_int(1, MAX_DISPARITY_PX), default=SGBM_MAX_DISPARITY, metavar="PX",
                   help="SGBM search range when no disparity is given (default %(default)s)")
    p.set_defaults(func=cmd_generate, parser=p)


_GENERATE_MODES = {
    "pair": _Mode("one pair", frozenset({"reference", "target", "road_mask", "disparity", "model_json"}),
                  ("reference", "target", "road_mask"), hint=" (or --dataset and --root: a whole dataset)"),
    "virtual": _Mode("--virtual", frozenset({"virtual", "reference", "road_mask", "calib", "disparity", "shift",
                                             "rotate", "label_out", "model_json"}),
                     ("reference", "road_mask", "calib", "label_out")),
    "dataset": _Mode("--dataset", frozenset({"dataset", "root", "split", "disparity_dir", "disparity_source",
                                             "lidar_densify", "cache_dir", "shard", "workers", "overwrite",
                                             "labels"}),
                     ("root",)),
}


def cmd_generate(args: argparse.Namespace) -> int:
    """``freespace generate``: one pair, a whole dataset, or (``--virtual``) one view from another pose."""
    from freespace.datagen.generate import FitOptions

    mode = "virtual" if args.virtual else "dataset" if args.dataset else "pair"
    _check_mode(args.parser, args, _GENERATE_MODES, mode)
    _refuse_folders(args, ("reference", "target", "road_mask", "disparity", "calib"))
    options = FitOptions(robust=args.robust, inlier_threshold=args.inlier_threshold, max_disparity=args.max_disparity)
    if mode == "virtual":
        from freespace.datagen.virtual import generate_virtual_pair

        print(generate_virtual_pair(args.reference, args.road_mask, args.calib, args.disparity, shift=args.shift,
                                    rotate=args.rotate, out=args.out, label_out=args.label_out,
                                    model_json=args.model_json, options=options).summary())
        return 0
    if mode == "pair":
        from freespace.datagen.generate import generate_pair

        result = generate_pair(args.reference, args.target, args.road_mask, args.disparity, out=args.out,
                               model_json=args.model_json, options=options)
        m = result.model
        print(f"roll {m.roll_deg:+.4f}°  ϰ {m.kappa_hat:.6f}  κ {m.kappa:.3f}  inliers {m.num_inliers}/{m.num_valid}"
              f"  rms {m.rms:.3f} px  → {args.out}")
        return 0
    from freespace.datagen.generate import generate_dataset

    def run(dataset: Any, out: str, **kwargs: Any) -> dict[str, Any]:
        from freespace.data.label_tree import hold_labels_record

        dataset, tree = _generate_labels(args, dataset)
        with hold_labels_record(out, tree, dataset.root, args.labels, args.overwrite):
            return generate_dataset(dataset, out, **kwargs)

    return _run_dataset(args, run, options, "generated", needs_right="the DS-Generator warps the right image")


def _generate_labels(args: argparse.Namespace, dataset: Any) -> tuple[Any, dict[str, Any] | None]:
    """``generate --dataset``'s road labels: with ``--labels TREE`` the dataset's frames that have a label
    there, labelled from it, and the tree's record (:func:`~freespace.data.label_tree.labelled_from_tree`);
    without, the dataset as it is (refused in one line naming ``--labels`` when none of its frames has a label)
    and None."""
    from freespace.data.label_tree import labelled_from_tree
    from freespace.errors import DatasetError

    if args.labels is None:
        if not any(dataset.has_label(f) for f in dataset.frames):
            raise DatasetError(f"{args.dataset} at {args.root} has no road labels, which the DS-Generator fits the "
                               f"road model to; label it with `freespace autolabel --dataset {args.dataset} --root "
                               f"{args.root} --out TREE` and give {param('labels')} TREE")
        return dataset, None
    return labelled_from_tree(dataset, args.labels, args.dataset, args.root, args.split)


# --- autolabel -----------------------------------------------------------------------------------------


def _autolabel_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.disparity import DISPARITY_SOURCES
    from freespace.datagen.autolabel import AutolabelOptions
    from freespace.geometry import SGBM_MAX_DISPARITY
    from freespace.geometry.road_model import CAMERA_HEIGHT_RANGE_M

    one = p.add_argument_group("one image")
    one.add_argument("--reference", metavar="L.png", help="left image")
    one.add_argument("--target", metavar="R.png", help="right image (the disparity is computed with SGBM)")
    one.add_argument("--disparity", metavar="D", help="left disparity (KITTI uint16 .png, .npy, .pfm) instead of "
                                                      "--target")
    one.add_argument("--confidence", metavar="C.png", help="also write the label's confidence (8-bit grey PNG)")
    one.add_argument("--model-json", metavar="M.json", help="also write the road model and statistics as JSON")
    one.add_argument("--calib", metavar="CALIB.txt", help="KITTI calibration (a frame's, or KITTI raw's "
                                                          "calib_cam_to_cam.txt): the baseline from P2/P3")
    one.add_argument("--baseline", type=bounded_float(MIN_BASELINE_M, MAX_BASELINE_M), metavar="B",
                     help="the baseline in metres (instead of --calib)")
    g = p.add_argument_group("dataset")
    _add_dataset_root(g, required=False)
    g.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of <frame>.png|.npy|.pfm disparities")
    g.add_argument("--disparity-source", dest="disparity_source", default="auto",
                   choices=[s for s in DISPARITY_SOURCES if s != "none"],  # a label needs a disparity
                   help="auto: file, else depth + camera, else cached SGBM (default); depth, lidar, sgbm: only that")
    g.add_argument("--lidar-densify", type=bounded_float(0, MAX_LIDAR_FILL_PX), metavar="PX",
                   help="--disparity-source lidar: fill holes within "
                                                                      "PX pixels of a point")
    g.add_argument("--cache-dir", metavar="DIR", help="SGBM disparity cache (default ~/.cache/freespace/sgbm)")
    g.add_argument("--shard", metavar="K/N", help="only the K-th of N disjoint parts of the frames (K from 1)")
    g.add_argument("--workers", type=_WORKERS, default=1, help="processes (default 1)")
    g.add_argument("--overwrite", action="store_true",
                   help="replace what an earlier run with other settings labelled in --out")
    g.add_argument("--propagate-from", metavar="TREE",
                   help="instead of labelling frames: carry the road that later frames of each drive saw near the "
                        "car back into TREE's labels (an autolabel tree of this dataset), written to --out as a new "
                        "tree; far road and road beyond parked cars get labels, conflicts become don't care")
    p.add_argument("--out", required=True, help="label image LABEL.png (one image) or folder (dataset)")
    d = AutolabelOptions()
    g = p.add_argument_group("method")
    g.add_argument("--curb-height", type=bounded_float(0, MAX_CURB_HEIGHT_M, low_open=True), default=d.curb_height,
                   metavar="M",
                   help="smallest step off the road to tell apart, metres (default %(default)s)")
    g.add_argument("--camera-height", type=bounded_float(*CAMERA_HEIGHT_RANGE_M, why="the heights every road fit "
                                                         "keeps"), default=d.camera_height, metavar="M",
                   help=f"camera height above the road when the baseline is unknown, {CAMERA_HEIGHT_RANGE_M[0]:g}–"
                        f"{CAMERA_HEIGHT_RANGE_M[1]:g} m (default %(default)s)")
    g.add_argument("--noise", type=bounded_float(0, MAX_NOISE_PX, low_open=True), metavar="PX",
                   help="disparity noise in pixels (default: estimated)")
    g.add_argument("--max-disparity", type=bounded_int(1, MAX_DISPARITY_PX), default=SGBM_MAX_DISPARITY, metavar="PX",
                   help="SGBM search range (default %(default)s)")
    g.add_argument("--max-camber", dest="max_camber_deg", type=bounded_float(0, 30), default=d.max_camber_deg,
                   metavar="DEG", help="lanes beside the road on a plane of their own that meets it without a step "
                                       "and lies below it (a cambered street) are road when its roll differs by at "
                                       "most DEG (default %(default)s; 0: one plane)")
    p.set_defaults(func=cmd_autolabel, parser=p)


_AUTOLABEL_MODES = {
    "one": _Mode("one image", frozenset({"reference", "target", "disparity", "confidence", "model_json", "calib",
                                         "baseline"}),
                 ("reference",), hint=" and --target or --disparity (or --dataset and --root: a whole dataset)"),
    "dataset": _GENERATE_MODES["dataset"],
    "propagate": _Mode("--propagate-from", frozenset({"dataset", "root", "split", "disparity_source", "lidar_densify",
                                                      "cache_dir", "propagate_from"}), ("root",)),
}


def cmd_autolabel(args: argparse.Namespace) -> int:
    """``freespace autolabel``: a road label from disparity, for one left image or a whole dataset."""
    from freespace.datagen.autolabel import AutolabelOptions, autolabel_dataset, autolabel_pair

    mode = "propagate" if args.propagate_from else "dataset" if args.dataset else "one"
    _check_mode(args.parser, args, _AUTOLABEL_MODES, mode)
    if mode == "propagate":
        return _propagate(args)
    _refuse_folders(args, ("reference", "target", "disparity", "calib"))
    options = AutolabelOptions(curb_height=args.curb_height, camera_height=args.camera_height, noise=args.noise,
                               max_disparity=args.max_disparity, max_camber_deg=args.max_camber_deg)
    if mode == "one":
        result = autolabel_pair(args.reference, args.target, args.disparity, out=args.out, confidence=args.confidence,
                                calib=args.calib, baseline=args.baseline, model_json=args.model_json, options=options)
        s = result.stats
        print(f"road {100 * s['road_fraction']:.1f}%  labelled {100 * s['coverage']:.1f}%  roll "
              f"{result.model.roll_deg:+.2f}°  noise {s['noise_px']:.2f} px  → {args.out}")
        return 0
    return _run_dataset(args, autolabel_dataset, options, "labelled")


def _propagate(args: argparse.Namespace) -> int:
    """``freespace autolabel --propagate-from TREE``: the tree's labels with the road later frames saw."""
    from freespace.datagen.propagate import propagate_dataset

    method = [a.option_strings[0] for a in args.parser._actions
              if a.dest in ("curb_height", "camera_height", "noise", "max_disparity", "max_camber_deg")
              and getattr(args, a.dest) != a.default]
    if method:
        raise InvalidOptionError(f"{', '.join(method)} set how frames are labelled, and --propagate-from labels none "
                                 f"(it carries TREE's labels along each drive); leave them out")
    s = propagate_dataset(_open_dataset(args), args.propagate_from, args.out)
    print(f"{s['frames']} frames: labelled {100 * s['mean_coverage_before']:.1f}% → {100 * s['mean_coverage']:.1f}%, "
          f"road {100 * s['mean_road_before']:.1f}% → {100 * s['mean_road_fraction']:.1f}% (gained "
          f"{100 * s['mean_gained']:.2f}%, conflicts {100 * s['mean_conflicts']:.2f}%) → {args.out}")
    return 0


# --- synth ---------------------------------------------------------------------------------------------


def _range(text: str) -> tuple[float, float]:
    """``"MIN,MAX"`` → ``(MIN, MAX)`` (argparse type: a bad value is a one-line usage error)."""
    try:
        lo, hi = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be MIN,MAX (two numbers), got {text!r}") from None
    return lo, hi


def _synth_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.synthetic.dataset import MAX_FRAMES
    from freespace.data.synthetic.scene import MAX_ROLL_DEG
    from freespace.io.codecs import MAX_IMAGE_SIDE

    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--num", type=bounded_int(1, MAX_FRAMES), required=True, help="number of frames")
    p.add_argument("--width", type=bounded_int(32, MAX_IMAGE_SIDE), default=640, help="image width (default 640)")
    p.add_argument("--height", type=bounded_int(32, MAX_IMAGE_SIDE), default=480, help="image height (default 480)")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    p.add_argument("--frames-per-scenario", type=bounded_int(1, MAX_FRAMES), default=10,
                   help="frames per drive (default 10)")
    p.add_argument("--non-planar", action="store_true", help="roads with slopes and camber")
    p.add_argument("--baseline", type=bounded_float(MIN_BASELINE_M, MAX_BASELINE_M),
                   help="fixed baseline in metres (default: 0.3–1.6 per scenario)")
    p.add_argument("--max-roll", dest="max_roll_deg", type=bounded_float(0, MAX_ROLL_DEG), default=3.0,
                   help="rig roll range ± degrees, at most 15 (default 3)")
    p.add_argument("--baselines", type=_range, default=(0.3, 1.6), metavar="MIN,MAX",
                   help="baseline range in metres, drawn per drive when --baseline is not given (default 0.3,1.6)")
    p.add_argument("--camera-heights", type=_range, default=(1.4, 2.0), metavar="MIN,MAX",
                   help="camera height range above the road in metres, within 0.3–6 (default 1.4,2.0)")
    p.add_argument("--pitches", dest="pitches_deg", type=_range, default=(-2.0, 2.0), metavar="MIN,MAX",
                   help="rig pitch range in degrees, positive = looking down at the road (default -2,2)")
    p.add_argument("--weather", help="comma-separated subset of clear,cloudy,rain,sunset,dusk,fog (default all)")
    p.add_argument("--workers", type=_WORKERS, default=1, help="processes (default 1)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a dataset rendered with other settings in --out (default: refuse)")
    p.set_defaults(func=cmd_synth)


def cmd_synth(args: argparse.Namespace) -> int:
    """``freespace synth``: render the built-in stereo road dataset as a KITTI road tree."""
    from freespace.data.synthetic import WEATHERS, SynthConfig, write_dataset

    weathers = tuple(w.strip() for w in args.weather.split(",")) if args.weather else WEATHERS
    config = SynthConfig(width=args.width, height=args.height, frames_per_scenario=args.frames_per_scenario,
                         planar=not args.non_planar, baseline=args.baseline, max_roll_deg=args.max_roll_deg,
                         baselines=args.baselines, camera_heights=args.camera_heights, pitches_deg=args.pitches_deg,
                         weathers=weathers)
    rows = write_dataset(args.out, args.num, seed=args.seed, config=config, workers=args.workers,
                         overwrite=args.overwrite)
    scenarios = len({r["scenario"] for r in rows})
    print(f"{len(rows)} stereo frames in {scenarios} scenarios ({args.width}×{args.height}) → {args.out}")
    return 0


# --- datasets info | split -----------------------------------------------------------------------------


def _datasets_parser(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="datasets_command", required=True, metavar="SUBCOMMAND")
    q = sub.add_parser("info", help="counts per split and category, what is there, every problem",
                       description="Count frames per split and category, report resolution and which files "
                                   "are there, open every file and list every problem by frame. Exit 0 only "
                                   "when there is none.")
    _add_dataset_root(q, split=False)
    q.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of user-supplied disparities")
    q.add_argument("--seed", type=_SEED, default=0, help="seed of the train/val/test split shown (default 0)")
    _split_options(q, "shown")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.set_defaults(func=cmd_datasets_info)
    q = sub.add_parser("split", help="write the paper's train/val/test split by scenario as list files",
                       description="Split the labelled frames (every frame of kitti-raw, which has no labels of its "
                                   "own) by scenario with the paper's sizes (289 → 173/58/58, 300 → 180/60/60, else "
                                   "60/20/20 %), or with --by time each drive into contiguous time blocks (train "
                                   "first, then val, then test; never interleaved frames, which at 10 Hz are near "
                                   "duplicates), and write train.txt, val.txt, test.txt (frame names).")
    _add_dataset_root(q)
    q.add_argument("--seed", type=_SEED, default=0, help="shuffling seed (default 0)")
    _split_options(q, "written")
    q.add_argument("--out", required=True, help="folder for the list files")
    q.set_defaults(func=cmd_datasets_split)


def _split_options(q: argparse.ArgumentParser, what: str) -> None:
    """``--by``, ``--fractions`` and ``--gap`` of ``datasets info`` and ``datasets split``."""
    from freespace.data.splits import SPLIT_BY

    q.add_argument("--by", choices=SPLIT_BY, default="scenario",
                   help=f"split {what}: whole scenarios/drives (default) or contiguous time blocks of each drive")
    q.add_argument("--fractions", metavar="TRAIN,VAL,TEST",
                   help="shares of the frames (default: the paper's sizes by scenario, 0.6,0.2,0.2 by time), "
                        "e.g. 0.8,0,0.2")
    q.add_argument("--gap", type=bounded_int(0, MAX_FRAME_COUNT), default=0, metavar="N",
                   help="--by time: frames of each drive left out between two blocks (default 0)")


def cmd_datasets_info(args: argparse.Namespace) -> int:
    """``freespace datasets info``: counts, what is there, and every problem by frame."""
    from freespace.data.info import dataset_info, format_info
    from freespace.data.splits import parse_fractions

    flags = _flags(build_parser({"datasets"}), ["datasets", "info"])
    info = dataset_info(args.dataset, args.root, progress=not args.no_progress, seed=args.seed,
                        disparity_dir=args.disparity_dir, by=args.by, gap=args.gap,
                        fractions=parse_fractions(args.fractions) if args.fractions is not None else None,
                        spell=lambda name: flags.get(name, name))
    print(format_info(info))
    return 1 if info["problems"] else 0


def cmd_datasets_split(args: argparse.Namespace) -> int:
    """``freespace datasets split``: the paper's train/val/test split by scenario, as list files."""
    from freespace.data.splits import split_dataset

    splits = split_dataset(args.dataset, args.root, args.out, split=args.split, by=args.by, seed=args.seed,
                           fractions=args.fractions, gap=args.gap)
    print(" ".join(f"{k} {len(v)}" for k, v in splits.items()) + f" → {args.out}/{{train,val,test}}.txt")
    return 0


# --- train, evaluate, evaluate-kitti -------------------------------------------------------------------


#: the flags of the :class:`~freespace.engine.config.TrainConfig` fields that are not ``--name-with-dashes``
CONFIG_FLAGS = {"splits_dir": "--splits"}


def _config_flag(name: str) -> str:
    """The flag of the :class:`~freespace.engine.config.TrainConfig` field ``name``."""
    return CONFIG_FLAGS.get(name, "--" + name.replace("_", "-"))


class _FromFile:
    """The default of an option that ``--config`` gave: its typed ``value``, checked when the file was read
    (and not again: :meth:`~freespace.engine.config.TrainConfig.from_checked`), and its ``text`` for the help."""

    def __init__(self, value: Any, text: Any) -> None:
        self.value, self.text = value, text

    def __str__(self) -> str:
        return str(self.text)


def _add_config_options(p: argparse.ArgumentParser, names: Collection[str] | None = None,
                        values: Mapping[str, Any] | None = None, *, checked: bool = False) -> None:
    """An option for each :class:`~freespace.engine.config.TrainConfig` field in ``names`` (default: all), its
    ``dest`` the field's name (so that an error naming the parameter names this flag), with the field's help,
    choices and default; ``values`` (typed) replace the defaults, and a field given there is no longer required
    (``checked``: they are ``--config``'s, whose file checked them: :class:`_FromFile`). Flags are passed on as
    given (numbers converted); TrainConfig parses and checks them, as the file's values were."""
    from freespace.engine.options import options

    for o in options(names, values):
        text = FreespaceError(o.help).render(_config_flag).replace("%", "%%")  # its parameters as flags
        if o.choices is not None:
            text += f"; one of {', '.join(o.choices)}"
        if o.default is not None and o.default is not False:
            text += "; default %(default)s"
        default = _FromFile(values[o.name], o.default) if checked and values and o.name in values else o.default
        kwargs: dict[str, Any] = {"dest": o.name, "default": default, "help": text}
        if o.kind is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs.update(type=o.kind, metavar=o.metavar or ("NAME" if o.choices is not None else None),
                          required=o.required)
        p.add_argument(_config_flag(o.name), **kwargs)


def _config_values(args: argparse.Namespace, names: Collection[str] | None = None) -> dict[str, Any]:
    """The values of the options :func:`_add_config_options` added, by field name."""
    from freespace.engine.options import options

    return {o.name: getattr(args, o.name) for o in options(names)}


def _train_parser(p: argparse.ArgumentParser, config: Mapping[str, Any] | None = None) -> None:
    p.add_argument("--config", metavar="YAML", help="options from a YAML file, e.g. a run's config.yaml; "
                                                    "flags given as well override it")
    _add_config_options(p, values=config, checked=True)
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_train)


def _config_file_options(argv: Sequence[str]) -> dict[str, Any] | None:
    """The options in ``--config YAML`` when ``argv`` has one (read before the real parse, as timm does), as
    typed values (:func:`~freespace.engine.config.read_config_yaml`); without one, ``--resume --out RUN`` reads
    the run's own ``RUN/config.yaml``, so that a run resumes from its folder alone."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config", action="append")
    pre.add_argument("--out")
    pre.add_argument("--resume", action="store_true")
    known, _ = pre.parse_known_args(argv)
    if known.config is None:
        if not (known.resume and known.out):
            return None
        saved = Path(known.out) / "config.yaml"
        if not saved.is_file():
            raise InvalidOptionError(f"--resume needs a run folder with config.yaml and checkpoints/last.ckpt; "
                                     f"{known.out} has no config.yaml: give the --out of a run that freespace train "
                                     f"started, or leave out --resume to train anew")
        known.config = [str(saved)]
    if len(known.config) > 1:  # the last would win without a word, as a key given twice in one file would
        raise InvalidOptionError(f"--config is given {len(known.config)} times ({', '.join(known.config)}); give one "
                                 f"file (flags given as well override it)")
    if not known.config[0].strip():
        raise InvalidOptionError("--config is empty; give it a YAML file, or leave it out")
    from freespace.engine.config import read_config_yaml

    return read_config_yaml(known.config[0])


def cmd_train(args: argparse.Namespace) -> int:
    """``freespace train``: train a network, with or without the homography augmentation."""
    from freespace.engine.config import TrainConfig
    from freespace.engine.train import run_training

    values = _config_values(args)
    config = TrainConfig.from_checked({k: v.value for k, v in values.items() if isinstance(v, _FromFile)},
                                      **{k: v for k, v in values.items() if not isinstance(v, _FromFile)})
    metrics = run_training(config, resume=args.resume, progress=not args.no_progress)
    from freespace.engine.data import is_rank_zero

    if not is_rank_zero():
        return 0
    print(" ".join(f"{k} {metrics[k]:.4f}"
                   for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"))
          + f"  → {config.out}/metrics.json")
    return 0


def _evaluate_parser(p: argparse.ArgumentParser) -> None:
    from freespace.evaluation.labelled import LABEL_FORMATS

    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="a .ckpt from a run folder")
    src.add_argument("--onnx", help="a model exported with `freespace export --format onnx`")
    d = p.add_argument_group("a dataset's frames (its labels)")
    _add_dataset_root(d, required=False)
    d.add_argument("--subset", default="test", help="train, val, test (the run's lists) or all labelled frames "
                                                    "(default test)")
    d.add_argument("--splits", dest="splits_dir", metavar="DIR",
                   help="train.txt/val.txt/test.txt (default: the checkpoint's run folder)")
    f = p.add_argument_group("a labelled folder (real sets' label images, paired with the images by name)")
    f.add_argument("--images", metavar="DIR", help="the images")
    f.add_argument("--labels", metavar="DIR", help="the label images (frames without one are not scored)")
    f.add_argument("--label-format", choices=LABEL_FORMATS,
                   help="kitti: KITTI road ground truth (<cat>_road_<id>.png); binary: non-zero = road; class-id: "
                        "class ids (--road IDS); palette: class colours (--road R,G,B)")
    f.add_argument("--road", metavar="VALUES", help="class-id: the road's ids (CamVid: 3); palette: the road's "
                                                    "colours R,G,B[;R,G,B] (Cityscapes: 128,64,128)")
    f.add_argument("--ignore", metavar="VALUES", help="don't-care ids, grey values or colours, as --road "
                                                      "(CamVid: 11)")
    f.add_argument("--tolerance", type=bounded_int(0, 64), metavar="LEVELS",
                   help="palette: a pixel within LEVELS of a colour on every channel has it (default 8)")
    p.add_argument("--threads", type=_WORKERS, help="ONNX Runtime threads (default: the cores this process may use)")
    p.add_argument("--no-overlays", action="store_true", help="labelled folder: skip the TP/FN/FP overlays")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (a new one, or one this command wrote)")
    p.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args: argparse.Namespace) -> int:
    """``freespace evaluate``: a model on a subset of a dataset's split, or on a labelled folder."""
    from freespace.inference.evaluate import evaluate, evaluate_report

    m = evaluate(args.out, checkpoint=args.checkpoint, onnx=args.onnx, dataset=args.dataset, root=args.root,
                 split=args.split, subset=args.subset, splits_dir=args.splits_dir, images=args.images,
                 labels=args.labels, label_format=args.label_format, road=args.road, ignore=args.ignore,
                 tolerance=args.tolerance, threads=args.threads, overlays=not args.no_overlays,
                 progress=not args.no_progress)
    print(evaluate_report(m, args.out))
    return 0


def _evaluate_kitti_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("--gt", required=True, help="ground-truth folder (gt_image_2: <cat>_road_<id>.png)")
    p.add_argument("--pred", required=True, help="prediction folder (<cat>_road_<id>.png or <cat>_<id>.png)")
    p.add_argument("--bev", action="store_true", help="evaluate in the benchmark's bird's-eye view (needs --calib)")
    p.add_argument("--calib", metavar="CALIB_DIR", help="calibration files <cat>_<id>.txt (for --bev)")
    p.add_argument("--out", required=True, help="output JSON")
    p.set_defaults(func=cmd_evaluate_kitti)


def cmd_evaluate_kitti(args: argparse.Namespace) -> int:
    """``freespace evaluate-kitti``: KITTI confidence maps against KITTI ground truth (perspective)."""
    from freespace.evaluation.kitti import evaluate_kitti, kitti_table

    print(kitti_table(evaluate_kitti(args.gt, args.pred, args.out, calib=args.calib, bev=args.bev)))
    return 0


# --- predict, export, kitti-submit ---------------------------------------------------------------------


def _predict_parser(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="a training checkpoint (.ckpt)")
    src.add_argument("--onnx", help="a model exported with `freespace export --format onnx`")
    p.add_argument("--input", required=True, help="an image, a folder of images, a quoted glob ('frames/*.png') "
                                                   "or a video")
    p.add_argument("--batch-size", type=bounded_int(1, MAX_BATCH_SIZE), default=4,
                   help="frames per network call (default 4)")
    p.add_argument("--shard", metavar="K/N", help="only the K-th of N disjoint parts of the images, by file name "
                                                  "(K from 1); shards share --out")
    p.add_argument("--no-overlays", action="store_true",
                   help="write the confidence PNGs only, not overlays/ (for real time: an overlay PNG costs ~3 masks)")
    p.add_argument("--threads", type=_WORKERS, help="the network's CPU threads: ONNX Runtime's, or PyTorch's with "
                                                    "--checkpoint (default: the cores this process may use)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.add_argument("--out", required=True, help="output folder (PNGs), or OUT.mp4: the overlaid video")
    p.set_defaults(func=cmd_predict)


def cmd_predict(args: argparse.Namespace) -> int:
    """``freespace predict``: road confidence PNGs (KITTI format) and overlays, or the overlaid video."""
    from freespace.inference.predict import predict, predict_report

    summary = predict(args.input, args.out, checkpoint=args.checkpoint, onnx=args.onnx, threads=args.threads,
                      batch_size=args.batch_size, shard=args.shard, overlays=not args.no_overlays,
                      progress=not args.no_progress)
    print(predict_report(summary, args.out, args.shard))
    return 0


def _export_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, help="a training checkpoint (.ckpt) to export")
    p.add_argument("--format", dest="fmt", choices=("onnx", "torchscript"), required=True,
                   help="onnx (ONNX Runtime, `predict --onnx`) or torchscript")
    p.add_argument("--int8", action="store_true", help="onnx: int8 static quantisation (QDQ, per channel), "
                                                       "calibrated on --calibration's frames")
    p.add_argument("--calibration", metavar="DIR", help="with --int8: a folder (or glob, or video) of real frames "
                                                        "like those the model will see")
    p.add_argument("--fp16", action="store_true", help="onnx: weights and computation in float16 (about half the "
                                                       "size; input and output stay float32), checked against the "
                                                       "checkpoint's probabilities")
    p.add_argument("--out", required=True, help="output file")
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    """``freespace export``: ONNX or TorchScript, validated against PyTorch."""
    from freespace.inference.export import export_model, export_report

    if args.fp16 and args.int8:
        raise InvalidOptionError("--fp16 and --int8 exclude each other: a model is exported in float16 or in int8; "
                                 "leave out one of them")
    if args.int8 != (args.calibration is not None):
        raise InvalidOptionError("--int8 and --calibration DIR go together: int8 quantisation is calibrated on real "
                                 "frames" if args.int8 else "--calibration is for --int8: add --int8, or leave it out")
    print(export_report(export_model(args.checkpoint, args.fmt, args.out, calibration=args.calibration,
                                     fp16=args.fp16)))
    return 0


def _adapt_parser(p: argparse.ArgumentParser) -> None:
    from freespace.engine.adapt import BOUNDS as B
    from freespace.engine.adapt import AdaptSettings as D

    p.add_argument("--model", required=True, help="a published model folder with its checkpoint "
                                                   "(models/real-road-fast)")
    p.add_argument("--input", required=True, help="your unlabelled frames: a folder, a quoted glob or a video")
    p.add_argument("--out", required=True, help="the new model folder (outside --model)")
    p.add_argument("--source", help="frames of the model's own training drives (its card names them), rehearsed "
                                    "so that it forgets nothing")
    p.add_argument("--epochs", type=B["epochs"], default=D.epochs,
                   help=f"rounds over the frames; the teacher relabels them after each (default {D.epochs})")
    p.add_argument("--minutes", type=B["minutes"],
                   help="a time limit for the training (default none)")
    p.add_argument("--threshold", type=B["threshold"], default=D.threshold,
                   help=f"a pixel is a label where the teacher is this sure of it (default {D.threshold})")
    p.add_argument("--lr", type=B["lr"], default=D.lr,
                   help=f"AdamW learning rate (default {D.lr:g})")
    p.add_argument("--batch-size", type=B["batch_size"], default=D.batch_size,
                   help=f"frames per step (default {D.batch_size})")
    p.add_argument("--ema", type=B["ema"], default=D.ema,
                   help=f"the teacher's moving-average decay per step (default {D.ema})")
    p.add_argument("--max-drift", type=B["max_drift"], default=D.max_drift,
                   help=f"the collapse guard: the most the held-out frames' road share may move (default "
                        f"{D.max_drift})")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    p.add_argument("--threads", type=_WORKERS, help="CPU threads (default: the cores this process may use)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.set_defaults(func=cmd_adapt)


def cmd_adapt(args: argparse.Namespace) -> int:
    """``freespace adapt``: self-train a published model on unlabelled frames; write a new model folder."""
    from freespace.engine.adapt import adapt

    s = adapt(args.model, args.input, args.out, source=args.source, epochs=args.epochs, minutes=args.minutes,
              threshold=args.threshold, lr=args.lr, batch_size=args.batch_size, ema=args.ema,
              max_drift=args.max_drift, seed=args.seed, progress=not args.no_progress, threads=args.threads)
    b, a = s["before"], s["after"]
    print(f"adapted {s['model']} on {s['frames']} frames ({s['skipped']} unreadable skipped) in {s['seconds'] / 60:.1f}"
          f" min, {s['rounds']} rounds; held-out road share {100 * b['road_share']:.1f} % → {100 * a['road_share']:.1f}"
          f" %, mean confidence {100 * b['confidence']:.1f} % → {100 * a['confidence']:.1f} % → {args.out}")
    return 0


def _kitti_submit_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, help="a training checkpoint (.ckpt)")
    p.add_argument("--root", required=True, metavar="KITTI_DIR", help="folder holding data_road/testing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_kitti_submit)


def cmd_kitti_submit(args: argparse.Namespace) -> int:
    """``freespace kitti-submit``: the testing split in the benchmark's BEV format, zipped."""
    from freespace.inference.submission import kitti_submit, submit_report

    print(submit_report(kitti_submit(args.checkpoint, args.root, args.out, progress=not args.no_progress), args.out))
    return 0


# --- reproduce, demo -----------------------------------------------------------------------------------

REPRODUCE_OPTIONS = ("dataset", "root", "epochs", "patience", "val_window", "min_delta", "lr", "batch_size",
                     "image_size", "workers", "max_frames", "preset", "encoder_name", "encoder_weights",
                     "virtual_shift", "virtual_rotate", "virtual_prob")


def _reproduce_parser(p: argparse.ArgumentParser) -> None:
    from freespace.experiments.variants import MAX_SEEDS

    _add_config_options(p, REPRODUCE_OPTIONS, values={"dataset": None, "root": None})  # not with --tables
    p.add_argument("--models", help="all (the paper's six networks) or a comma-separated list (default all)")
    p.add_argument("--seeds", type=bounded_int(1, MAX_SEEDS), default=3,
                   help="seeds per network and variant (default 3)")
    p.add_argument("--variants", help="comma-separated arms: X, HA-X (DS-Generator views), "
                   "X-dup (the control: X with HA-X's number of steps), X-long (X with twice the epochs and "
                   "patience), HV-X (road-plane virtual views), HAV-X (both), X-auto (training labels from "
                   "--autolabels), X-mix (the dataset's labels on 20%% of the training drives, --autolabels' on the "
                   "rest) (default: --protocol's, else X,HA-X,X-dup)")
    p.add_argument("--autolabels", metavar="DIR", help="for X-auto and X-mix: the label tree of --root that "
                   "`freespace autolabel --dataset` wrote")
    p.add_argument("--test-root", metavar="[NAME=]DIR", action="append",
                   help="also test every run on all labelled frames of this dataset (same --dataset layout; e.g. "
                   "other rigs): rows with test_set = NAME, or shifted without one; repeat for more sets")
    p.add_argument("--only", metavar="NETWORK,VARIANT,SEED", help="run one cell of the protocol (e.g. unet,HA-X,0; "
                   "seed in 0…--seeds−1), writing only its run folder (cluster array jobs); collect with --tables")
    p.add_argument("--tables", action="store_true", help="train nothing: rebuild index.json, the tables and the "
                   "figures from the run folders in --out")
    p.add_argument("--protocol", metavar="FILE", help="a study's protocol (YAML: its variants, the gains it reports, "
                   "its primary endpoint, named test sets and a reference line; or variants of its own, each with "
                   "its training data, which replace --dataset and --root; see freespace.experiments.protocol); "
                   "default: variants X,HA-X,X-dup, every gain of the variants run, no primary endpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (a new one, or one this command wrote)")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    """``freespace reproduce``: every network with and without the augmentation (and the control); tables,
    paired gains and figures; one cell with ``--only``, the tables alone with ``--tables``."""
    from freespace.experiments.reproduce import run_reproduce

    r = run_reproduce(args.out, protocol=args.protocol, tables=args.tables, models=args.models, seeds=args.seeds,
                      variants=args.variants, test_root=args.test_root, only=args.only, autolabels=args.autolabels,
                      progress=not args.no_progress, **_config_values(args, REPRODUCE_OPTIONS))
    if args.only:
        print(f"{r['runs'][0]['run']}: {r['runs'][0]['status']} (collect the cells with --tables)")
        return 0
    print(Path(args.out, "results.md").read_text().rstrip())
    print(f"{len(r['runs'])} runs → {args.out} (results.md, results.csv, gains.csv, figures/, index.json)")
    return 0


def _demo_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.synthetic.dataset import MAX_FRAMES

    p.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    p.add_argument("--num", dest="num_frames", type=bounded_int(1, MAX_FRAMES), default=60,
                   help="number of rendered frames (default 60)")
    p.add_argument("--full", action="store_true", help="the six-network protocol with three seeds (long)")
    p.add_argument("--epochs", type=bounded_int(1, MAX_EPOCHS), help="training epochs (default 12; 30 with --full)")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    """``freespace demo``: render a stereo scene, run the DS-Generator, write the pictures."""
    from freespace.demo import demo_report, run_demo

    text, ok = demo_report(run_demo(args.out, num_frames=args.num_frames, seed=args.seed, full=args.full,
                                    epochs=args.epochs), args.out)
    print(text)
    return 0 if ok else 1


# --- the command ---------------------------------------------------------------------------------------

# name: (one-line help, description, parser builder); each builder sets its handler as ``func``
COMMANDS: dict[str, tuple[str, str, Callable[..., None]]] = {
    "generate": ("fit the road model and write the DS-Generator image(s)",
                 "Fit the road disparity model to the road pixels of a stereo pair and warp the target (right) "
                 "image into the reference (left) view with the road homography; for one pair or every labelled "
                 "frame of a dataset. With --virtual: the reference image and its label from another camera pose, "
                 "through the road plane (no right image).", _generate_parser),
    "autolabel": ("road labels from disparity alone (no people): one left image or a whole dataset",
                  "Fit the road disparity model to the whole frame and label the pixels that agree with it (KITTI "
                  "colours: road magenta, non-road red, don't care black where the evidence is weak), with an 8-bit "
                  "confidence; for one left image (from --disparity, or SGBM with --target) or every frame of a "
                  "dataset, as a label tree that `train --labels` reads.", _autolabel_parser),
    "synth": ("render the built-in stereo road dataset (KITTI road layout)",
              "Render stereo road scenes (left, right, exact disparity, road label, calibration) as a KITTI road "
              "tree. Frame i depends only on the seed and i.", _synth_parser),
    "datasets": ("inspect datasets", "Inspect and check datasets.", _datasets_parser),
    "train": ("train a network (optionally with the homography or virtual-view augmentation)",
              "Train a segmentation network on a dataset's train split, validate each epoch, stop early on the "
              "validation F-score and test the best checkpoint. The run folder holds config.yaml, splits/, "
              "metrics.csv, checkpoints/ and metrics.json.", _train_parser),
    "evaluate": ("evaluate a model on labelled frames: metrics with intervals, per-frame scores, overlays",
                 "Evaluate a checkpoint or an ONNX model on a subset (train, val, test or all) of a dataset's "
                 "on-disk split, or on a labelled folder of real frames (KITTI ground truth, binary masks, class "
                 "ids, palette colours); writes metrics.json (pooled scores, frame-level bootstrap intervals), "
                 "per_frame.csv, overlays/ (TP green, FN red, FP blue) and pr_curve.png.",
                 _evaluate_parser),
    "evaluate-kitti": ("evaluate KITTI-format confidence maps like the KITTI road devkit",
                       "Evaluate 8-bit road confidence PNGs against KITTI road ground truth as the official devkit "
                       "does (256 thresholds, don't-care excluded, counts summed per category, MaxF, 11-point AP, "
                       "PRE/REC/FPR/FNR at MaxF); perspective view, or the benchmark's bird's-eye view with --bev "
                       "--calib.", _evaluate_kitti_parser),
    "predict": ("road confidence maps (KITTI 8-bit PNG) and overlays for images, or an overlaid video",
                "Predict every frame of an image, a folder, a glob or a video with a checkpoint or an ONNX model; "
                "writes <name>.png (8-bit road confidence, input size; 255 = sure road), overlays/<name>.png and "
                "summary.json (runtime per frame), or with --out OUT.mp4 the overlaid video.", _predict_parser),
    "export": ("export a checkpoint to ONNX or TorchScript (validated)",
               "Export a checkpoint to ONNX (dynamic batch, height and width) or TorchScript; the export is "
               "checked against PyTorch and the max abs difference printed.", _export_parser),
    "adapt": ("adapt a published road model to your camera's unlabelled frames",
              "Self-train a published model folder (its checkpoint) on unlabelled frames: a slowly moving teacher "
              "labels the pixels it is sure of, the student learns them on strongly augmented views; a collapse "
              "guard refuses a model that drifts to all road or no road. Writes a new model folder: model.onnx "
              "(float16), model.ckpt, README.md (the card), before_after.jpg and the run's record.", _adapt_parser),
    "kitti-submit": ("KITTI road testing predictions in the benchmark's BEV format",
                     "Predict data_road/testing and write bird's-eye-view confidence maps <cat>_road_<id>.png "
                     "(800×400, x −10…10 m, z 6…46 m) made with each frame's calibration as the devkit does, and "
                     "submission.zip.", _kitti_submit_parser),
    "reproduce": ("the paper's experiments: every network with and without HA; tables, figures",
                  "Train every chosen network on the original and on the augmented training set (same seeds, "
                  "budget, early stopping; --variants adds the virtual-view arms HV-X and HAV-X), test them, and "
                  "write results.md/.csv (mean ± std over seeds, each variant's gain over X), "
                  "figures and an index of the runs. Finished runs are skipped when run again.", _reproduce_parser),
    "demo": ("run the built-in demo end to end",
             "Render stereo road scenes, run the DS-Generator on them and write the results.", _demo_parser),
}


def build_parser(commands: Collection[str] | None = None,
                 config: Mapping[str, Any] | None = None) -> argparse.ArgumentParser:
    """The argument parser of the ``freespace`` command, with the options of ``commands`` (default: all;
    the others are listed but take no options). ``config``: option values read from ``train --config``."""
    parser = _Parser(prog="freespace", description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--version", action="version", version=f"freespace {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log messages")
    parser.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (summary, description, build) in COMMANDS.items():
        p = sub.add_parser(name, help=summary, description=description)
        if commands is None or name in commands:
            if build is _train_parser:
                _train_parser(p, config)
            else:
                build(p)
    return parser


def _refuse_extra_arguments(parser: argparse.ArgumentParser, extra: list[str], command: str | None) -> None:
    """Arguments no option took: an unknown option (with its value, a path or not) is named as such; the
    shell's expansion of an unquoted wildcard (``--input *.png`` gives one file to ``--input`` and the rest
    here: every one an existing path) gets a one-line hint to quote it; anything else argparse's error."""
    unknown = [a for a in extra if a.startswith("-") and not os.path.exists(a)]
    if unknown:
        raise InvalidOptionError(f"unknown option{'s' if len(unknown) > 1 else ''} {' '.join(unknown)}; see "
                                 f"`{parser.prog}{f' {command}' if command else ''} --help`")
    if all(os.path.exists(a) for a in extra):
        shown = " ".join(extra[:3]) + (f" … ({len(extra)} in all)" if len(extra) > 3 else "")
        raise InvalidOptionError(f"unexpected argument{'s' if len(extra) > 1 else ''} {shown}: the shell expanded an "
                                 f"unquoted wildcard into many files; quote the pattern, e.g. --input 'frames/*.png'")
    parser.error(f"unrecognized arguments: {' '.join(extra)}")
def _flags(parser: argparse.ArgumentParser, argv: Sequence[str]) -> dict[str, str]:
    """``{dest: flag}`` of every option of the (sub-)command ``argv`` runs (``{"image_size": "--image-size"}``):
    how an error's parameters are written on the command line (:meth:`FreespaceError.render`)."""
    flags: dict[str, str] = {}
    words = [a for a in argv if not a.startswith("-")]
    while parser is not None:
        sub = None
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                sub = next((action.choices[w] for w in words if w in action.choices), None)
            longs = [o for o in action.option_strings if o.startswith("--")]
            if longs:
                flags.setdefault(action.dest, longs[0])
        parser = sub
    return flags


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``freespace`` console script; returns the exit code.

    Ctrl-C ends a command with "interrupted" and exit code 130, ``SIGTERM`` (SLURM's time limit, ``kill``)
    with "terminated" and 143; both after the command's clean-ups (``finally`` blocks) have run.
    """
    from freespace.io.files import writing_as
    from freespace.runtime.log import setup_logging
    from freespace.runtime.signals import missing_extra, sigterm_raises

    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)  # the global options take no value
    parser: argparse.ArgumentParser | None = None
    with sigterm_raises():  # SIGTERM raises Terminated until the message is out
        try:
            config = _config_file_options(argv) if command == "train" else None
            parser = build_parser({command} if command else (), config)
            args, extra = parser.parse_known_args(argv)
            if extra:
                _refuse_extra_arguments(parser, extra, command)
            setup_logging(-1 if args.quiet else args.verbose)
            with writing_as(command or "freespace"):  # the mark of the files it writes (freespace.io.files)
                return int(args.func(args))
        except FreespaceError as exc:  # one line, even where a file name holds a newline (shown escaped)
            flags = _flags(parser or build_parser({command} if command else ()), argv)
            text = exc.render(lambda name: flags.get(name, name))
            message = "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)
            print(f"freespace: error: {message}", file=sys.stderr)
            return exc.exit_code
        except KeyboardInterrupt:
            print("freespace: interrupted", file=sys.stderr)
            return 130
        except Terminated as exc:
            print("freespace: terminated (SIGTERM)", file=sys.stderr)
            return exc.exit_code
        except ModuleNotFoundError as exc:  # a command of an extra in the base install (`pip install freespace`)
            if (message := missing_extra(exc, command)) is None:
                raise
            print(f"freespace: error: {message}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
