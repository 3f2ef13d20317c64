"""The commands that make and inspect data: generate, autolabel, synth and datasets (info, split)."""

from __future__ import annotations

import argparse
from functools import partial

from freespace.cli.shared import (
    SEED,
    WORKERS,
    Mode,
    add_dataset_root,
    check_mode,
    dataset_of,
    flags_of,
    number_pair,
    refuse_folders,
    run_dataset,
)
from freespace.errors import InvalidOptionError
from freespace.limits import (
    MAX_BASELINE_M,
    MAX_CURB_HEIGHT_M,
    MAX_DISPARITY_PX,
    MAX_FRAME_COUNT,
    MAX_INLIER_THRESHOLD_PX,
    MAX_LIDAR_FILL_PX,
    MAX_NOISE_PX,
    MAX_POSE,
    MIN_BASELINE_M,
    bounded_float,
    bounded_int,
    bounded_triple,
)

# --- generate ------------------------------------------------------------------------------------------


def generate_parser(p: argparse.ArgumentParser) -> None:
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
    add_dataset_root(g, required=False)
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
    p.add_argument("--workers", type=WORKERS, default=1, help="processes, for --dataset (default 1)")
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
    "pair": Mode("one pair", frozenset({"reference", "target", "road_mask", "disparity", "model_json"}),
                 ("reference", "target", "road_mask"), hint=" (or --dataset and --root: a whole dataset)"),
    "virtual": Mode("--virtual", frozenset({"virtual", "reference", "road_mask", "calib", "disparity", "shift",
                                            "rotate", "label_out", "model_json"}),
                    ("reference", "road_mask", "calib", "label_out")),
    "dataset": Mode("--dataset", frozenset({"dataset", "root", "split", "disparity_dir", "disparity_source",
                                            "lidar_densify", "cache_dir", "shard", "workers", "overwrite",
                                            "labels"}),
                    ("root",)),
}


def cmd_generate(args: argparse.Namespace) -> int:
    """``freespace generate``: one pair, a whole dataset, or (``--virtual``) one view from another pose."""
    from freespace.datagen.generate import FitOptions

    mode = "virtual" if args.virtual else "dataset" if args.dataset else "pair"
    check_mode(args.parser, args, _GENERATE_MODES, mode)
    refuse_folders(args, ("reference", "target", "road_mask", "disparity", "calib"))
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
    from freespace.datagen.generate import generate_with_labels

    run = partial(generate_with_labels, labels=args.labels, name=args.dataset, root=args.root, split=args.split)
    return run_dataset(args, run, options, "generated", needs_right="the DS-Generator warps the right image")


# --- autolabel -----------------------------------------------------------------------------------------


def autolabel_parser(p: argparse.ArgumentParser) -> None:
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
    add_dataset_root(g, required=False)
    g.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of <frame>.png|.npy|.pfm disparities")
    g.add_argument("--disparity-source", dest="disparity_source", default="auto",
                   choices=[s for s in DISPARITY_SOURCES if s != "none"],  # a label needs a disparity
                   help="auto: file, else depth + camera, else cached SGBM (default); depth, lidar, sgbm: only that")
    g.add_argument("--lidar-densify", type=bounded_float(0, MAX_LIDAR_FILL_PX), metavar="PX",
                   help="--disparity-source lidar: fill holes within "
                                                                      "PX pixels of a point")
    g.add_argument("--cache-dir", metavar="DIR", help="SGBM disparity cache (default ~/.cache/freespace/sgbm)")
    g.add_argument("--shard", metavar="K/N", help="only the K-th of N disjoint parts of the frames (K from 1)")
    g.add_argument("--workers", type=WORKERS, default=1, help="processes (default 1)")
    g.add_argument("--overwrite", action="store_true",
                   help="replace what an earlier run with other settings labelled in --out")
    g.add_argument("--propagate-from", metavar="TREE",
                   help="instead of labelling frames: carry the road that later frames of each drive saw near the "
                        "car back into TREE's labels (an autolabel tree of this dataset), written to --out as a new "
                        "tree; far road and road beyond parked cars get labels, conflicts become don't care")
    g.add_argument("--look-from", metavar="TREE",
                   help="instead of labelling frames: learn each drive's road look from TREE's labels (ImageNet "
                        "features of the lane ahead against the not road) and make TREE's road that does not look "
                        "like road (tram ballast, gravel, pavements level with the road) don't care, written to "
                        "--out as a new tree")
    g.add_argument("--look-veto", type=bounded_float(0, 1, low_open=True, high_open=True), default=0.5, metavar="P",
                   help="--look-from: road whose look gives a road probability under P becomes don't care "
                        "(default %(default)s)")
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
    "one": Mode("one image", frozenset({"reference", "target", "disparity", "confidence", "model_json", "calib",
                                        "baseline"}),
                ("reference",), hint=" and --target or --disparity (or --dataset and --root: a whole dataset)"),
    "dataset": _GENERATE_MODES["dataset"],
    "propagate": Mode("--propagate-from", frozenset({"dataset", "root", "split", "disparity_source", "lidar_densify",
                                                     "cache_dir", "propagate_from"}), ("root",)),
    "look": Mode("--look-from", frozenset({"dataset", "root", "split", "look_from", "look_veto"}), ("root",)),
}


def cmd_autolabel(args: argparse.Namespace) -> int:
    """``freespace autolabel``: a road label from disparity, for one left image or a whole dataset."""
    from freespace.datagen.autolabel import AutolabelOptions, autolabel_dataset, autolabel_pair

    mode = ("look" if args.look_from else "propagate" if args.propagate_from else "dataset" if args.dataset
            else "one")
    check_mode(args.parser, args, _AUTOLABEL_MODES, mode)
    if mode in ("propagate", "look"):
        _refuse_method(args)
        return _propagate(args) if mode == "propagate" else _look(args)
    refuse_folders(args, ("reference", "target", "disparity", "calib"))
    options = AutolabelOptions(curb_height=args.curb_height, camera_height=args.camera_height, noise=args.noise,
                               max_disparity=args.max_disparity, max_camber_deg=args.max_camber_deg)
    if mode == "one":
        result = autolabel_pair(args.reference, args.target, args.disparity, out=args.out, confidence=args.confidence,
                                calib=args.calib, baseline=args.baseline, model_json=args.model_json, options=options)
        s = result.stats
        print(f"road {100 * s['road_fraction']:.1f}%  labelled {100 * s['coverage']:.1f}%  roll "
              f"{result.model.roll_deg:+.2f}°  noise {s['noise_px']:.2f} px  → {args.out}")
        return 0
    return run_dataset(args, autolabel_dataset, options, "labelled")


def _refuse_method(args: argparse.Namespace) -> None:
    """Refuse the options that set how frames are labelled to the passes over a tree (they label none)."""
    method = [a.option_strings[0] for a in args.parser._actions
              if a.dest in ("curb_height", "camera_height", "noise", "max_disparity", "max_camber_deg")
              and getattr(args, a.dest) != a.default]
    if method:
        given = "--look-from" if args.look_from else "--propagate-from"
        raise InvalidOptionError(f"{', '.join(method)} set how frames are labelled, and {given} labels none "
                                 f"(it changes TREE's labels); leave them out")


def _propagate(args: argparse.Namespace) -> int:
    """``freespace autolabel --propagate-from TREE``: the tree's labels with the road later frames saw."""
    from freespace.datagen.propagate import propagate_dataset

    s = propagate_dataset(dataset_of(args), args.propagate_from, args.out)
    print(f"{s['frames']} frames: labelled {100 * s['mean_coverage_before']:.1f}% → {100 * s['mean_coverage']:.1f}%, "
          f"road {100 * s['mean_road_before']:.1f}% → {100 * s['mean_road_fraction']:.1f}% (gained "
          f"{100 * s['mean_gained']:.2f}%, conflicts {100 * s['mean_conflicts']:.2f}%) → {args.out}")
    return 0


def _look(args: argparse.Namespace) -> int:
    """``freespace autolabel --look-from TREE``: the tree's road that does not look like road made don't care."""
    from freespace.datagen.options import LookOptions
    from freespace.datagen.road_look import look_check_dataset

    s = look_check_dataset(dataset_of(args), args.look_from, args.out, options=LookOptions(veto=args.look_veto))
    print(f"{s['frames']} frames: road {100 * s['mean_road_before']:.1f}% → {100 * s['mean_road_fraction']:.1f}% "
          f"({100 * s['mean_vetoed']:.2f}% of the pixels vetoed by their look) → {args.out}")
    return 0


# --- synth ---------------------------------------------------------------------------------------------


#: ``"MIN,MAX"`` → ``(MIN, MAX)`` (argparse type: a bad value is a one-line usage error)
_range = number_pair("MIN,MAX", "two numbers")


def synth_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.synthetic.dataset import MAX_FRAMES
    from freespace.data.synthetic.scene import MAX_ROLL_DEG
    from freespace.io.codecs import MAX_IMAGE_SIDE

    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--num", type=bounded_int(1, MAX_FRAMES), required=True, help="number of frames")
    p.add_argument("--width", type=bounded_int(32, MAX_IMAGE_SIDE), default=640, help="image width (default 640)")
    p.add_argument("--height", type=bounded_int(32, MAX_IMAGE_SIDE), default=480, help="image height (default 480)")
    p.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
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
    p.add_argument("--workers", type=WORKERS, default=1, help="processes (default 1)")
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


def datasets_parser(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="datasets_command", required=True, metavar="SUBCOMMAND")
    q = sub.add_parser("info", help="counts per split and category, what is there, every problem",
                       description="Count frames per split and category, report resolution and which files "
                                   "are there, open every file and list every problem by frame. Exit 0 only "
                                   "when there is none.")
    add_dataset_root(q, split=False)
    q.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of user-supplied disparities")
    q.add_argument("--seed", type=SEED, default=0, help="seed of the subsets shown (default 0)")
    _split_options(q, "shown")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.set_defaults(func=cmd_datasets_info, parser=q)
    q = sub.add_parser("split", help="divide the labelled frames into the subsets train/val/test and write their "
                                     "subset lists",
                       description="Split the labelled frames (every frame of kitti-raw, which has no labels of its "
                                   "own) by scenario with the paper's sizes (289 → 173/58/58, 300 → 180/60/60, else "
                                   "60/20/20 %), or with --by time each drive into contiguous time blocks (train "
                                   "first, then val, then test; never interleaved frames, which at 10 Hz are near "
                                   "duplicates), and write train.txt, val.txt, test.txt (frame names).")
    add_dataset_root(q)
    q.add_argument("--seed", type=SEED, default=0, help="shuffling seed (default 0)")
    _split_options(q, "written")
    q.add_argument("--out", required=True, help="folder for the subset lists")
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

    flags = flags_of(args.parser, [])
    info = dataset_info(args.dataset, args.root, progress=not args.no_progress, seed=args.seed,
                        disparity_dir=args.disparity_dir, by=args.by, gap=args.gap,
                        fractions=parse_fractions(args.fractions) if args.fractions is not None else None,
                        spell=lambda name: flags.get(name, name))
    print(format_info(info))
    return 1 if info["problems"] else 0


def cmd_datasets_split(args: argparse.Namespace) -> int:
    """``freespace datasets split``: the labelled frames divided into the subsets train/val/test, written as
    their subset lists."""
    from freespace.data.splits import split_dataset

    splits = split_dataset(args.dataset, args.root, args.out, split=args.split, by=args.by, seed=args.seed,
                           fractions=args.fractions, gap=args.gap)
    print(" ".join(f"{k} {len(v)}" for k, v in splits.items()) + f" → {args.out}/{{train,val,test}}.txt")
    return 0
