"""The ``freespace`` command. Thin: parses options, calls the library, reports.

Heavy modules are imported inside each subcommand so that ``freespace generate`` starts fast and
never imports torch. Every :class:`~freespace.errors.FreespaceError` ends the command with a one-line
message on stderr and exit code 2; a dataset run with failed frames exits with 1.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from freespace import __version__
from freespace.errors import FreespaceError, InvalidOptionError

log = logging.getLogger("freespace")

DATASETS = ("kitti", "synth", "synthia", "carla", "syn-stereo", "generic")


def _open_dataset(args: argparse.Namespace):  # -> StereoRoadDataset (import kept lazy)
    from freespace.data.base import get_dataset

    options = {"disparity": args.disparity_source, "cache_dir": args.cache_dir,
               "max_disparity": getattr(args, "max_disparity", 128)}
    if args.disparity_dir is not None:
        if args.dataset not in ("kitti", "synth"):
            raise InvalidOptionError("--disparity-dir is for KITTI road trees; other layouts name their "
                                     "disparity folder in freespace.yaml")
        options["disparity_dir"] = args.disparity_dir
    return get_dataset(args.dataset, args.root, args.split, **options)


def _add_dataset_root(p: argparse.ArgumentParser | argparse._ArgumentGroup, required: bool = True,
                      split: bool = True) -> None:
    """``--dataset``, ``--root`` and (optionally) ``--split``, shared by every command that reads a dataset."""
    p.add_argument("--dataset", choices=DATASETS, required=required,
                   help="layout: kitti (KITTI road; synth = the renderer's output), synthia, carla/syn-stereo, generic")
    p.add_argument("--root", metavar="DIR", required=required, help="dataset folder")
    if split:
        p.add_argument("--split", help="on-disk split (KITTI: training or testing; default: the first)")


def _add_dataset_options(p: argparse.ArgumentParser, required: bool) -> None:
    g = p.add_argument_group("dataset")
    _add_dataset_root(g, required)
    g.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of <frame>.png|.npy|.pfm disparities")
    g.add_argument("--disparity-source", choices=("auto", "file", "sgbm", "none"), default="auto",
                   help="auto: file, else depth + camera, else cached SGBM (default)")
    g.add_argument("--cache-dir", metavar="DIR", help="SGBM disparity cache (default ~/.cache/freespace/sgbm)")


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("road fit")
    g.add_argument("--inlier-threshold", type=float, default=1.0, metavar="PX",
                   help="disparity residual (pixels) above which a road pixel is an outlier (default 1.0)")
    g.add_argument("--no-robust", dest="robust", action="store_false",
                   help="plain least squares over all valid road pixels (no outlier rejection)")
    g.add_argument("--max-disparity", type=int, default=128, metavar="PX",
                   help="SGBM search range when no disparity is given (default 128)")


def _fit_options(args: argparse.Namespace):  # -> FitOptions (import kept lazy)
    from freespace.generate import FitOptions

    return FitOptions(robust=args.robust, inlier_threshold=args.inlier_threshold, max_disparity=args.max_disparity)


def cmd_generate(args: argparse.Namespace) -> int:
    """``freespace generate``: one pair or a whole dataset (or, with --virtual, one view from another pose)."""
    if args.virtual:
        from freespace.generate import generate_virtual_pair

        print(generate_virtual_pair(args.reference, args.road_mask, args.calib, args.disparity, shift=args.shift,
                                    rotate=args.rotate, out=args.out, label_out=args.label_out,
                                    model_json=args.model_json, options=_fit_options(args),
                                    unused={"--target": args.target, "--dataset": args.dataset}).summary())
        return 0
    if args.calib or args.shift or args.rotate or args.label_out:
        raise InvalidOptionError("--calib, --shift, --rotate and --label-out are for --virtual")
    pair = [args.reference, args.target, args.road_mask]
    if args.dataset is None:
        if not all(pair):
            raise InvalidOptionError("give --reference, --target and --road-mask (one pair), or --dataset and "
                                     "--root (a dataset)")
        from freespace.generate import generate_pair

        result = generate_pair(args.reference, args.target, args.road_mask, args.disparity, out=args.out,
                               model_json=args.model_json, options=_fit_options(args))
        m = result.model
        print(f"roll {m.roll_deg:+.4f}°  ϰ {m.kappa_hat:.6f}  κ {m.kappa:.3f}  inliers {m.num_inliers}/{m.num_valid}"
              f"  rms {m.rms:.3f} px  → {args.out}")
        return 0
    if any(pair) or args.disparity or args.model_json:
        raise InvalidOptionError("--dataset generates a whole dataset; --reference/--target/--road-mask/"
                                 "--disparity/--model-json are for one pair, leave them out")
    if args.root is None:
        raise InvalidOptionError("--dataset needs --root DIR, the dataset's folder")
    from freespace.generate import generate_dataset

    dataset = _open_dataset(args)
    summary = generate_dataset(dataset, args.out, workers=args.workers, options=_fit_options(args))
    failed = summary["failed"]
    print(f"{summary['generated']} generated, {summary['skipped']} already done, {len(failed)} failed "
          f"of {summary['frames']} frames → {args.out}")
    for name, reason in failed.items():
        print(f"  failed {name}: {reason}")
    return 1 if failed else 0


def cmd_synth(args: argparse.Namespace) -> int:
    """``freespace synth``: render the built-in stereo road dataset as a KITTI road tree."""
    from freespace.data.synthetic import WEATHERS, SynthConfig, write_dataset

    weathers = tuple(w.strip() for w in args.weather.split(",")) if args.weather else WEATHERS
    config = SynthConfig(width=args.width, height=args.height, frames_per_scenario=args.frames_per_scenario,
                         planar=not args.non_planar, baseline=args.baseline, max_roll_deg=args.max_roll,
                         weathers=weathers)
    rows = write_dataset(args.out, args.num, seed=args.seed, config=config, workers=args.workers)
    scenarios = len({r["scenario"] for r in rows})
    print(f"{len(rows)} stereo frames in {scenarios} scenarios ({args.width}×{args.height}) → {args.out}")
    return 0


def cmd_datasets_info(args: argparse.Namespace) -> int:
    """``freespace datasets info``: counts, what is there, and every problem by frame."""
    from freespace.data.info import dataset_info, format_info

    info = dataset_info(args.dataset, args.root, progress=not args.no_progress, seed=args.seed,
                        disparity_dir=args.disparity_dir)
    print(format_info(info))
    return 1 if info["problems"] else 0


def cmd_datasets_split(args: argparse.Namespace) -> int:
    """``freespace datasets split``: the paper's train/val/test split by scenario, as list files."""
    from freespace.data.base import get_dataset
    from freespace.data.splits import make_splits, write_splits

    dataset = get_dataset(args.dataset, args.root, args.split, disparity="none")
    labelled = [(f.name, f.scenario) for f in dataset.frames if f.label is not None]
    if not labelled:
        raise InvalidOptionError(f"split {dataset.split!r} of {args.root} has no labelled frames to split")
    splits = make_splits(labelled, seed=args.seed)
    write_splits(args.out, splits)
    print(" ".join(f"{k} {len(v)}" for k, v in splits.items()) + f" → {args.out}/{{train,val,test}}.txt")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """``freespace evaluate``: a checkpoint on a dataset split."""
    from freespace.engine.evaluate import evaluate_checkpoint

    m = evaluate_checkpoint(args.checkpoint, args.dataset, args.root, args.out, split=args.split,
                            splits_dir=args.splits, on_disk_split=args.disk_split, progress=not args.no_progress)
    print(" ".join(f"{k} {m[k]:.4f}" for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"))
          + f"  ({m['frames']} frames) → {args.out}")
    return 0


def cmd_evaluate_kitti(args: argparse.Namespace) -> int:
    """``freespace evaluate-kitti``: KITTI confidence maps against KITTI ground truth (perspective)."""
    from freespace.io import write_json
    from freespace.kitti_eval import evaluate_kitti_dirs

    if args.bev and not args.calib:
        raise InvalidOptionError("--bev needs --calib CALIB_DIR (the frames' <cat>_<id>.txt calibration files)")
    results = evaluate_kitti_dirs(args.gt, args.pred, calib_dir=args.calib if args.bev else None)
    write_json(args.out, results)
    print(f"{'category':<10} {'images':>6} {'MaxF':>7} {'AP':>7} {'PRE':>7} {'REC':>7} {'FPR':>7} {'FNR':>7}")
    for cat, r in results.items():
        print(f"{cat:<10} {r['images']:>6} " + " ".join(f"{100 * r[k]:7.2f}" for k in ("max_f", "ap", "pre", "rec", "fpr", "fnr")))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    """``freespace train``: train a network, with or without the homography augmentation."""
    from freespace.engine.config import TrainConfig, parse_size
    from freespace.engine.train import run_training

    config = TrainConfig(dataset=args.dataset, root=args.root, out=args.out, model=args.model, preset=args.preset,
                         split=args.split, augment=args.augment, epochs=args.epochs, batch_size=args.batch_size,
                         lr=args.lr, momentum=args.momentum, weight_decay=args.weight_decay, patience=args.patience,
                         image_size=parse_size(args.image_size), seed=args.seed, devices=args.devices, num_nodes=args.num_nodes,
                         strategy=args.strategy, workers=args.workers, splits=args.splits, max_frames=args.max_frames,
                         disparity=args.disparity_source, cache_dir=args.cache_dir, tensorboard=args.tensorboard,
                         virtual_shift=args.virtual_shift, virtual_rotate=args.virtual_rotate,
                         virtual_prob=args.virtual_prob)
    config.check()
    metrics = run_training(config, resume=args.resume, progress=not args.no_progress)
    from freespace.engine.data import is_rank_zero

    if not is_rank_zero():
        return 0
    print(" ".join(f"{k} {metrics[k]:.4f}" for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"))
          + f"  → {args.out}/metrics.json")
    return 0


def cmd_predict(args: argparse.Namespace) -> int:
    """``freespace predict``: road confidence PNGs (KITTI format) and overlays."""
    from freespace.infer import Predictor, predict_folder

    predictor = Predictor(checkpoint=args.checkpoint, onnx=args.onnx)
    summary = predict_folder(predictor, args.input, args.out, batch_size=args.batch_size, progress=not args.no_progress)
    print(f"{summary['frames']} images, {summary['seconds_per_frame'] * 1000:.1f} ms per frame → {args.out}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """``freespace export``: ONNX or TorchScript, validated against PyTorch."""
    from freespace.infer import export_model

    r = export_model(args.checkpoint, args.format, args.out)
    print(f"{r['format']} → {r['path']}  max abs difference to PyTorch {r['max_abs_diff']:.2e} "
          f"(sizes {', '.join('×'.join(map(str, s[2:])) for s in r['checked_sizes'])})")
    return 0


def cmd_kitti_submit(args: argparse.Namespace) -> int:
    """``freespace kitti-submit``: the testing split in the benchmark's BEV format, zipped."""
    from freespace.infer import kitti_submit

    r = kitti_submit(args.checkpoint, args.root, args.out, progress=not args.no_progress)
    print(f"{r['frames']} bird's-eye-view maps → {args.out}; upload {r['zip']}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """``freespace demo``: render a stereo scene, run the DS-Generator, write the pictures."""
    from freespace.demo import run_demo

    result = run_demo(args.out, num_frames=args.num, seed=args.seed, full=args.full, epochs=args.epochs)
    print(f"{'frame':<12} {'weather':<8} {'roll':>7} {'fit':>7} {'SGBM fit':>8}   road |L−R|  road |L−G|")
    for f in result["frames"]:
        sgbm = f"{f['sgbm_roll_deg']:+8.3f}" if f["sgbm_roll_deg"] is not None else f"{'—':>8}"
        print(f"{f['frame']:<12} {f['weather']:<8} {f['true_roll_deg']:+7.3f} {f['fitted_roll_deg']:+7.3f} "
              f"{sgbm}   {f['road_mae_right']:10.1f}  {f['road_mae_generated']:10.1f}")
    print(f"on the road the generated view differs from the left image by {result['mean_road_mae_generated']:.1f} "
          f"grey levels on average, the raw right image by {result['mean_road_mae_right']:.1f}")
    if "results_md" in result:
        print()
        print(Path(result["results_md"]).read_text().rstrip())
    print(f"figures: {result['figures']}, {args.out}/experiment/figures   ({result['seconds']:.0f} s)")
    return 1 if result["generate_failed"] else 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    """``freespace reproduce``: every network with and without the augmentation; tables and figures."""
    from freespace.engine.config import parse_size
    from freespace.experiments.reproduce import reproduce
    from freespace.models import list_models

    models = list_models() if args.models == "all" else [m.strip() for m in args.models.split(",") if m.strip()]
    r = reproduce(args.dataset, args.root, args.out, models=models, seeds=args.seeds, epochs=args.epochs,
                  image_size=parse_size(args.image_size), patience=args.patience, batch_size=args.batch_size,
                  workers=args.workers, max_frames=args.max_frames, progress=not args.no_progress,
                  variants=args.variants)
    print(Path(args.out, "results.md").read_text().rstrip())
    print(f"{len(r['runs'])} runs → {args.out} (results.md, results.csv, figures/, index.json)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``freespace`` command."""
    parser = argparse.ArgumentParser(prog="freespace", description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--version", action="version", version=f"freespace {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log messages")
    parser.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("generate", help="fit the road model and write the DS-Generator image(s)",
                       description="Fit the road disparity model to the road pixels of a stereo pair and warp "
                                   "the target (right) image into the reference (left) view with the road "
                                   "homography; for one pair or every labelled frame of a dataset.")
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
    virt.add_argument("--calib", metavar="CALIB.txt", help="KITTI calibration (P2, P3; Tr_cam_to_road without --disparity)")
    virt.add_argument("--shift", metavar="DX,DY,DZ", help="camera centre move in metres (+x right, +y down; default 0,0,0)")
    virt.add_argument("--rotate", metavar="ROLL,PITCH,YAW", help="degrees about z, x, y, R = R_yaw·R_pitch·R_roll "
                      "(default 0,0,0)")
    virt.add_argument("--label-out", metavar="VL.png", help="the view's label, KITTI colours (don't care black)")
    _add_dataset_options(p, required=False)
    p.add_argument("--workers", type=int, default=1, help="processes, for --dataset (default 1)")
    p.add_argument("--out", required=True, help="output image (one pair) or folder (dataset)")
    _add_fit_options(p)
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("synth", help="render the built-in stereo road dataset (KITTI road layout)",
                       description="Render stereo road scenes (left, right, exact disparity, road label, "
                                   "calibration) as a KITTI road tree. Frame i depends only on the seed and i.")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--num", type=int, required=True, help="number of frames")
    p.add_argument("--width", type=int, default=640, help="image width (default 640)")
    p.add_argument("--height", type=int, default=480, help="image height (default 480)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--frames-per-scenario", type=int, default=10, help="frames per drive (default 10)")
    p.add_argument("--non-planar", action="store_true", help="roads with slopes and camber")
    p.add_argument("--baseline", type=float, help="fixed baseline in metres (default: 0.3–1.6 per scenario)")
    p.add_argument("--max-roll", type=float, default=3.0, help="rig roll range ± degrees (default 3)")
    p.add_argument("--weather", help="comma-separated subset of clear,cloudy,rain,sunset,dusk,fog (default all)")
    p.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("datasets", help="inspect datasets", description="Inspect and check datasets.")
    dsub = p.add_subparsers(dest="datasets_command", required=True, metavar="SUBCOMMAND")
    q = dsub.add_parser("info", help="counts per split and category, what is there, every problem",
                        description="Count frames per split and category, report resolution and which files "
                                    "are there, open every file and list every problem by frame. Exit 0 only "
                                    "when there is none.")
    _add_dataset_root(q, split=False)
    q.add_argument("--disparity-dir", metavar="DIR", help="KITTI: folder of user-supplied disparities")
    q.add_argument("--seed", type=int, default=0, help="seed of the train/val/test split shown (default 0)")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.set_defaults(func=cmd_datasets_info)

    q = dsub.add_parser("split", help="write the paper's train/val/test split by scenario as list files",
                        description="Split the labelled frames by scenario with the paper's sizes (289 → "
                                    "173/58/58, 300 → 180/60/60, else 60/20/20 %%) and write train.txt, val.txt, "
                                    "test.txt (frame names).")
    _add_dataset_root(q)
    q.add_argument("--seed", type=int, default=0, help="shuffling seed (default 0)")
    q.add_argument("--out", required=True, help="folder for the list files")
    q.set_defaults(func=cmd_datasets_split)

    p = sub.add_parser("train", help="train a network (optionally with the homography augmentation)",
                       description="Train a segmentation network on a dataset's train split, validate each epoch, "
                                   "stop early on the validation F-score and test the best checkpoint. The run "
                                   "folder holds config.yaml, splits/, metrics.csv, checkpoints/ and metrics.json.")
    _add_dataset_root(p)
    p.add_argument("--model", default="unet", help="segnet, unet, deeplabv3plus, denseaspp, dupsampling, gscnn")
    p.add_argument("--preset", default="light", help="light (CPU) or paper")
    p.add_argument("--augment", default="none", help="none, homography (adds the DS-Generator views), virtual "
                   "(random road-plane virtual views, no right image needed) or homography,virtual")
    p.add_argument("--virtual-shift", default="0.5,0.2,0", metavar="DX,DY,DZ",
                   help="--augment virtual: camera moves drawn in ± these metres (default 0.5,0.2,0)")
    p.add_argument("--virtual-rotate", default="3,3,3", metavar="ROLL,PITCH,YAW",
                   help="--augment virtual: rotations drawn in ± these degrees (default 3,3,3)")
    p.add_argument("--virtual-prob", type=float, default=0.5, help="--augment virtual: share of samples warped (0.5)")
    p.add_argument("--epochs", type=int, default=50)
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--lr", type=float, default=0.001)
    p.add_argument("--momentum", type=float, default=0.9)
    p.add_argument("--weight-decay", type=float, default=0.0)
    p.add_argument("--patience", type=int, default=10, help="early-stopping patience in epochs (default 10)")
    p.add_argument("--image-size", help="HxW all frames are resized to (default: the first frame's size)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--devices", type=int, default=1)
    p.add_argument("--num-nodes", type=int, default=1, help="machines, for multi-node DDP (see the README)")
    p.add_argument("--strategy", default="auto", help="auto or ddp")
    p.add_argument("--workers", type=int, default=0, help="data-loading processes")
    p.add_argument("--splits", metavar="DIR", help="train.txt/val.txt/test.txt to use (default: the paper's split)")
    p.add_argument("--max-frames", type=int, help="use only the first N labelled frames (quick runs)")
    p.add_argument("--disparity-source", choices=("auto", "file", "sgbm", "none"), default="auto")
    p.add_argument("--cache-dir", metavar="DIR", help="SGBM disparity cache")
    p.add_argument("--tensorboard", action="store_true", help="also write TensorBoard logs (needs tensorboard)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--out", required=True, metavar="RUN_DIR", help="run folder")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("evaluate", help="evaluate a checkpoint: metrics, TP/FN/FP overlays, PR curve",
                       description="Evaluate a training checkpoint on a split of a dataset; writes metrics.json, "
                                   "overlays/ (TP green, FN red, FP blue) and pr_curve.png.")
    p.add_argument("--checkpoint", required=True, help="a .ckpt from a run folder")
    _add_dataset_root(p, split=False)
    p.add_argument("--split", default="test", help="train, val, test (the run's lists) or all (default test)")
    p.add_argument("--splits", metavar="DIR", help="split lists (default: the checkpoint's run folder)")
    p.add_argument("--disk-split", help="the dataset's on-disk split (default: the first, e.g. KITTI training)")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--out", required=True, metavar="DIR")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("evaluate-kitti", help="evaluate KITTI-format confidence maps like the KITTI road devkit",
                       description="Evaluate 8-bit road confidence PNGs against KITTI road ground truth as the "
                                   "official devkit does (256 thresholds, don't-care excluded, counts summed per "
                                   "category, MaxF, 11-point AP, PRE/REC/FPR/FNR at MaxF); perspective view, or "
                                   "the benchmark's bird's-eye view with --bev --calib.")
    p.add_argument("--gt", required=True, help="ground-truth folder (gt_image_2: <cat>_road_<id>.png)")
    p.add_argument("--pred", required=True, help="prediction folder (<cat>_road_<id>.png or <cat>_<id>.png)")
    p.add_argument("--bev", action="store_true", help="evaluate in the benchmark's bird's-eye view (needs --calib)")
    p.add_argument("--calib", metavar="CALIB_DIR", help="calibration files <cat>_<id>.txt (for --bev)")
    p.add_argument("--out", required=True, help="output JSON")
    p.set_defaults(func=cmd_evaluate_kitti)

    p = sub.add_parser("predict", help="road confidence maps (KITTI 8-bit PNG) and overlays for images",
                       description="Predict every image of a file or folder with a checkpoint or an ONNX model; "
                                   "writes <name>.png (8-bit road confidence, input size; 255 = sure road), "
                                   "overlays/<name>.png and summary.json (runtime per frame).")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="a training checkpoint (.ckpt)")
    src.add_argument("--onnx", help="a model exported with `freespace export --format onnx`")
    p.add_argument("--input", required=True, help="an image or a folder of images")
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_predict)

    p = sub.add_parser("export", help="export a checkpoint to ONNX or TorchScript (validated)",
                       description="Export a checkpoint to ONNX (dynamic batch, height and width) or TorchScript; "
                                   "the export is checked against PyTorch and the max abs difference printed.")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--format", choices=("onnx", "torchscript"), required=True)
    p.add_argument("--out", required=True, help="output file")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("kitti-submit", help="KITTI road testing predictions in the benchmark's BEV format",
                       description="Predict data_road/testing and write bird's-eye-view confidence maps "
                                   "<cat>_road_<id>.png (800×400, x −10…10 m, z 6…46 m) made with each frame's "
                                   "calibration as the devkit does, and submission.zip.")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--root", required=True, metavar="KITTI_DIR", help="folder holding data_road/testing")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_kitti_submit)

    p = sub.add_parser("reproduce", help="the paper's experiments: every network with and without HA; tables, figures",
                       description="Train every chosen network on the original and on the augmented training set "
                                   "(same seeds, budget, early stopping), test them, and write results.md/.csv "
                                   "(mean ± std over seeds, HA gain), figures and an index of the runs. Finished "
                                   "runs are skipped when run again.")
    _add_dataset_root(p, split=False)
    p.add_argument("--models", default="all", help="all or a comma-separated list (default all)")
    p.add_argument("--seeds", type=int, default=3, help="seeds per network and variant (default 3)")
    p.add_argument("--variants", default="X,HA-X", help="comma-separated arms: X, HA-X (DS-Generator views), HV-X "
                   "(road-plane virtual views), HAV-X (both) (default X,HA-X)")
    p.add_argument("--epochs", type=int, default=50)
    p.add_argument("--patience", type=int, default=10)
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--image-size", help="HxW (default: the first frame's size)")
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--max-frames", type=int, help="use only the first N labelled frames")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--out", required=True, metavar="DIR")
    p.set_defaults(func=cmd_reproduce)

    p = sub.add_parser("demo", help="run the built-in demo end to end",
                       description="Render stereo road scenes, run the DS-Generator on them and write the results.")
    p.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    p.add_argument("--num", type=int, default=60, help="number of rendered frames (default 60)")
    p.add_argument("--full", action="store_true", help="the six-network protocol with three seeds (long)")
    p.add_argument("--epochs", type=int, help="training epochs (default 12; 30 with --full)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``freespace`` console script; returns the exit code."""
    from freespace.log import setup_logging

    parser = build_parser()
    args = parser.parse_args(argv)
    setup_logging(-1 if args.quiet else args.verbose)
    try:
        return int(args.func(args))
    except FreespaceError as exc:
        print(f"freespace: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("freespace: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
