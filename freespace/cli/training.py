"""The commands that train and score networks: train, evaluate, evaluate-kitti, adapt and reproduce."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from freespace.cli.config_options import FromFile, add_config_options, config_values
from freespace.cli.shared import CROP_TOP, SEED, WORKERS, add_dataset_root, number_pair
from freespace.limits import bounded_int

# --- train, evaluate, evaluate-kitti -------------------------------------------------------------------


def train_parser(p: argparse.ArgumentParser, config: Mapping[str, Any] | None = None) -> None:
    p.add_argument("--config", metavar="YAML", help="options from a YAML file, e.g. a run's config.yaml; "
                                                    "flags given as well override it")
    add_config_options(p, values=config, checked=True)
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_train)


def cmd_train(args: argparse.Namespace) -> int:
    """``freespace train``: train a network, with or without the homography augmentation."""
    from freespace.engine.config import TrainConfig
    from freespace.engine.train import run_training

    values = config_values(args)
    config = TrainConfig.from_checked({k: v.value for k, v in values.items() if isinstance(v, FromFile)},
                                      **{k: v for k, v in values.items() if not isinstance(v, FromFile)})
    metrics = run_training(config, resume=args.resume, progress=not args.no_progress)
    from freespace.engine.data import is_rank_zero

    if not is_rank_zero():
        return 0
    print(" ".join(f"{k} {metrics[k]:.4f}"
                   for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"))
          + f"  → {config.out}/metrics.json")
    return 0


def evaluate_parser(p: argparse.ArgumentParser) -> None:
    from freespace.evaluation.label_presets import LABEL_PRESETS
    from freespace.evaluation.labelled import LABEL_FORMATS

    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="a .ckpt from a run folder")
    src.add_argument("--onnx", help="a model exported with `freespace export --format onnx`")
    d = p.add_argument_group("a dataset's frames (its labels)")
    add_dataset_root(d, required=False)
    d.add_argument("--subset", default="test", help="the subset to score: train, val or test (as the subset lists "
                                                    "say) or all labelled frames of the split (default test)")
    d.add_argument("--splits", dest="splits_dir", metavar="DIR",
                   help="subset lists train.txt/val.txt/test.txt (default: RUN/splits/ when the checkpoint is in "
                        "RUN/checkpoints/ beside RUN/config.yaml, a training run's folder)")
    f = p.add_argument_group("a labelled folder (real sets' label images, paired with the images by name)")
    f.add_argument("--images", metavar="DIR", help="the images")
    f.add_argument("--labels", metavar="DIR", help="the label images (frames without one are not scored)")
    f.add_argument("--label-format", choices=LABEL_FORMATS,
                   help="kitti: KITTI road ground truth (<cat>_road_<id>.png); binary: non-zero = road; class-id: "
                        "class ids (--road IDS); palette: class colours (--road R,G,B)")
    f.add_argument("--road", metavar="VALUES", help="class-id: the road's ids (CamVid: 3; 16-bit labels: up to "
                                                    "65535); palette: the road's colours R,G,B[;R,G,B] (Cityscapes: "
                                                    "128,64,128); each must occur in the labels")
    f.add_argument("--ignore", metavar="VALUES", help="don't-care ids, grey values or colours, as --road "
                                                      "(CamVid: 11)")
    f.add_argument("--labels-like", metavar="SET", choices=tuple(LABEL_PRESETS),
                   help=f"instead of --label-format/--road/--ignore: the labels are a public set's "
                        f"({', '.join(LABEL_PRESETS)}; docs/own-data.md gives each one's source)")
    f.add_argument("--tolerance", type=bounded_int(0, 64), metavar="LEVELS",
                   help="palette: a pixel within LEVELS of a colour on every channel has it (default 8)")
    p.add_argument("--threads", type=WORKERS, help="ONNX Runtime threads (default: the cores this process may use)")
    p.add_argument("--tta", action="store_true", help="score the model as predict --tta runs it (light normalised, "
                                                      "mirror averaged)")
    p.add_argument("--crop-top", type=CROP_TOP, default=0.0, metavar="F",
                   help="score the model as predict --crop-top F runs it (the top F of each frame left out of the "
                        "network's input, scored not road; default 0)")
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
                 tolerance=args.tolerance, labels_like=args.labels_like, threads=args.threads,
                 overlays=not args.no_overlays, progress=not args.no_progress, tta=args.tta,
                 crop_top=args.crop_top)
    print(evaluate_report(m, args.out))
    return 0


def evaluate_kitti_parser(p: argparse.ArgumentParser) -> None:
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


# --- adapt ---------------------------------------------------------------------------------------------


def adapt_parser(p: argparse.ArgumentParser) -> None:
    from freespace.engine import adapt as A
    from freespace.engine import adapt_time as T
    from freespace.engine import norm_stats as N
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
                   help=f"frames per step, 2…{A.MAX_ADAPT_BATCH} and at most {A.MAX_STEP_PIXELS} pixels of the "
                        f"student's views (the model's height × half its width each); with --source a quarter of them "
                        f"are source frames (default {D.batch_size})")
    p.add_argument("--ema", type=B["ema"], default=D.ema,
                   help=f"the teacher's moving-average decay per step (default {D.ema})")
    p.add_argument("--max-drift", type=B["max_drift"], default=D.max_drift,
                   help=f"the collapse guard: the most the held-out frames' road share may move, a fraction of their "
                        f"pixels (default {D.max_drift}); whatever it is, the run also ends (exit 1, nothing written) "
                        f"when that share falls below {A.MIN_ROAD_RATIO:g}× or rises above {A.MAX_ROAD_RATIO:g}× the "
                        f"published model's, or when the loss is not finite or its mean over {A.LOSS_WINDOW} steps "
                        f"exceeds {A.LOSS_GROWTH:g}× its first step's (and ln 2)")
    p.add_argument("--norm-stats", choices=N.NORM_STATS, default=D.norm_stats,
                   help=f"the batch-norm statistics before self-training (AdaBN): 'frames' re-estimates them on up to "
                        f"{N.MAX_NORM_FRAMES} of your frames (refused for a checkpoint whose batch norms are folded "
                        f"into its convolutions, as models/real-road-unet's are), 'keep' keeps the checkpoint's, "
                        f"'auto' re-estimates them when the checkpoint holds a training run's and keeps folded ones "
                        f"(default {D.norm_stats})")
    p.add_argument("--across-time", choices=T.ACROSS_TIME, default=D.across_time,
                   help=f"carry each round's labels from the next frames along the road plane's homographies (the "
                        f"far road, the road beside the cars): 'auto' when your frames are a sequence (a video, or "
                        f"consecutive frames in name order: at least {100 * T.MIN_SEQUENCE_SHARE:.0f} %% of the "
                        f"consecutive pairs share a road homography), 'on', 'off' (default {D.across_time})")
    p.add_argument("--complete", action=argparse.BooleanOptionalAction, default=D.complete,
                   help="complete each round's labels by appearance: the pixels the teacher is unsure of take the "
                        "side of a graph cut on the frame's colours seeded with its confident labels (default on; "
                        "--no-complete: the confident labels alone)")
    p.add_argument("--release", type=B["release"], default=D.release, metavar="R",
                   help="with --complete, the graph cut may also relabel what the teacher is sure is not road within "
                        "R × the frame's height of its road: the far road and the lanes beside the cars that a "
                        f"teacher stops short of (0…1, default {D.release:g}: none)")
    p.add_argument("--release-far", type=B["release_far"], default=D.release_far, metavar="F",
                   help=f"with --release, only in the top F share of the road's rows: the far road, not the "
                        f"pavements beside the car (0…1, default {D.release_far:g}: every row)")
    p.add_argument("--look", type=number_pair("LO,HI", "two fractions of the width, e.g. 0.30,0.55"), metavar="LO,HI",
                   help="check each round's labels by their look: the road's look is learnt from the road in the "
                        "columns LO…HI of the width (the lane ahead: 0.30,0.55 where cars drive on the right, "
                        "0.45,0.70 on the left) against the not road, and road that does not look like it is not "
                        "trained on (pavements and verges the teacher takes; needs the ImageNet Lite0 weights; "
                        "default: no check)")
    p.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
    p.add_argument("--threads", type=WORKERS, help="CPU threads (default: the cores this process may use)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.set_defaults(func=cmd_adapt)


def cmd_adapt(args: argparse.Namespace) -> int:
    """``freespace adapt``: self-train a published model on unlabelled frames; write a new model folder."""
    from freespace.engine.adapt import adapt
    from freespace.io.files import shown_path

    s = adapt(args.model, args.input, args.out, source=args.source, epochs=args.epochs, minutes=args.minutes,
              threshold=args.threshold, lr=args.lr, batch_size=args.batch_size, ema=args.ema,
              max_drift=args.max_drift, seed=args.seed, norm_stats=args.norm_stats,
              across_time=args.across_time, complete=args.complete, release=args.release,
              release_far=args.release_far, look=args.look,
              progress=not args.no_progress, threads=args.threads)
    b, a = s["before"], s["after"]
    print(f"adapted {shown_path(s['model'])} on {s['frames']} frames ({s['skipped']} unreadable skipped) in "
          f"{s['seconds'] / 60:.1f} min, {s['rounds']} rounds; held-out road share {100 * b['road_share']:.1f} % → "
          f"{100 * a['road_share']:.1f} %, mean confidence {100 * b['confidence']:.1f} % → "
          f"{100 * a['confidence']:.1f} %; batch-norm statistics {s['norm_stats']} → {shown_path(args.out)}")
    return 0


# --- reproduce -----------------------------------------------------------------------------------------

REPRODUCE_OPTIONS = ("dataset", "root", "epochs", "patience", "val_window", "min_delta", "lr", "batch_size",
                     "image_size", "workers", "max_frames", "preset", "encoder_name", "encoder_weights",
                     "virtual_shift", "virtual_rotate", "virtual_prob")


def reproduce_parser(p: argparse.ArgumentParser) -> None:
    from freespace.experiments.variants import MAX_SEEDS

    add_config_options(p, REPRODUCE_OPTIONS, values={"dataset": None, "root": None})  # not with --tables
    p.add_argument("--models", help="all (the paper's six networks) or a comma-separated list (default all)")
    p.add_argument("--seeds", type=bounded_int(1, MAX_SEEDS), default=3,
                   help="seeds per network and variant (default 3)")
    p.add_argument("--variants", help="comma-separated arms: X, HA-X (DS-Generator views), "
                   "X-dup (the control: X with HA-X's number of steps), X-long (X with twice the epochs and "
                   "patience), HV-X (road-plane virtual views), HAV-X (both), X-auto (training labels from "
                   "--autolabels), X-mix (the dataset's labels on the share of the training drives the protocol's "
                   "controls give (mix_human_share), --autolabels' on the rest) (default: --protocol's, else "
                   "X,HA-X,X-dup)")
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
                      progress=not args.no_progress, **config_values(args, REPRODUCE_OPTIONS))
    if args.only:
        print(f"{r['runs'][0]['run']}: {r['runs'][0]['status']} (collect the cells with --tables)")
        return 0
    print(Path(args.out, "results.md").read_text().rstrip())
    print(f"{len(r['runs'])} runs → {args.out} (results.md, results.csv, gains.csv, figures/, index.json)")
    return 0
