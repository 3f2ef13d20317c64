"""The commands that run trained networks: predict, export, kitti-submit, and the built-in demo."""

from __future__ import annotations

import argparse

from freespace.cli.shared import CROP_TOP, SEED, WORKERS
from freespace.engine.model_folder import KERNELS
from freespace.errors import InvalidOptionError
from freespace.limits import MAX_BATCH_SIZE, MAX_EPOCHS, bounded_int

# --- predict, export, kitti-submit ---------------------------------------------------------------------


def predict_parser(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="a training checkpoint (.ckpt)")
    src.add_argument("--onnx", help="a model exported with `freespace export --format onnx`")
    p.add_argument("--input", required=True, help="an image, a folder of images, a quoted glob ('frames/*.png') "
                                                   "or a video")
    p.add_argument("--batch-size", type=bounded_int(1, MAX_BATCH_SIZE), default=4,
                   help="frames per network call (default 4)")
    p.add_argument("--shard", metavar="K/N", help="only the K-th of N disjoint parts of the images, by file name "
                                                  "(K from 1); shards share --out")
    p.add_argument("--overlay-format", choices=("png", "jpg"), default="png",
                   help="overlays/ as png (default) or jpg (about an eighth of a 1080p PNG's encoding time)")
    p.add_argument("--no-overlays", action="store_true",
                   help="write the confidence PNGs only, not overlays/ (for real time: an overlay PNG costs ~3 masks)")
    p.add_argument("--threads", type=WORKERS, help="the network's CPU threads: ONNX Runtime's, or PyTorch's with "
                                                    "--checkpoint (default: the cores this process may use)")
    p.add_argument("--tta", action="store_true", help="test-time augmentation: each frame seen with its light "
                                                      "normalised, averaged with its mirror image (two network passes "
                                                      "a frame; finds more road in dark or bright frames)")
    p.add_argument("--crop-top", type=CROP_TOP, default=0.0, metavar="F",
                   help="leave the top F of every frame (a fraction of its height in [0, 0.7), above a fixed "
                        "camera's horizon) out of the network's input, scored not road: the road fills more of "
                        "the input (default 0)")
    p.add_argument("--profile", action="store_true", help="also print each stage's time per frame: decode, "
                                                          "preprocess, network, postprocess, write")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (off a terminal there is none anyway)")
    p.add_argument("--out", required=True, help="output folder (PNGs), or OUT.mp4: the overlaid video")
    p.set_defaults(func=cmd_predict)


def cmd_predict(args: argparse.Namespace) -> int:
    """``freespace predict``: road confidence PNGs (KITTI format) and overlays, or the overlaid video."""
    from freespace.inference.predict import predict, predict_report

    summary = predict(args.input, args.out, checkpoint=args.checkpoint, onnx=args.onnx, threads=args.threads,
                      batch_size=args.batch_size, shard=args.shard, overlays=not args.no_overlays,
                      progress=not args.no_progress, tta=args.tta, overlay_format=args.overlay_format,
                      crop_top=args.crop_top)
    print(predict_report(summary, args.out, args.shard, profile=args.profile))
    return 0


def export_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, help="a training checkpoint (.ckpt) to export")
    p.add_argument("--format", dest="fmt", choices=("onnx", "torchscript", "folder"), required=True,
                   help="onnx (ONNX Runtime, `predict --onnx`), torchscript, or folder: a model folder like the "
                        "published ones (model.onnx in float16, model.ckpt, a card, metrics.json) for predict, adapt "
                        "and train --init")
    p.add_argument("--licence", help="folder: the model's licence, one line (the training data's terms, e.g. "
                                     "'CC BY-NC-SA 3.0 (KITTI)')")
    p.add_argument("--measured", action="append", metavar="EVAL_DIR", default=[],
                   help="folder: an output folder of `freespace evaluate` with this model, whose figures go into the "
                        "card (repeat for several sets)")
    p.add_argument("--kernels", choices=KERNELS, help="folder: model.ckpt's convolution kernels in float32 (the "
                                                      "weights as trained; the default) or float16 (as model.onnx "
                                                      "holds them; about half the size, for a big network)")
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
    """``freespace export``: ONNX or TorchScript, validated against PyTorch; or a whole model folder."""
    from freespace.inference.export import export_model, export_report

    if args.fmt == "folder":
        from freespace.engine.model_folder import export_model_folder, model_folder_report

        extra = [f for f, v in (("--int8", args.int8), ("--calibration", args.calibration), ("--fp16", args.fp16))
                 if v]
        if extra:
            raise InvalidOptionError(f"{extra[0]} is not for --format folder, whose model.onnx is float16 (as the "
                                     f"published folders'); leave it out")
        if args.licence is None:
            raise InvalidOptionError("--format folder needs --licence: the model's licence, from its training "
                                     "data's terms (a card names it)")
        print(model_folder_report(export_model_folder(args.checkpoint, args.out, licence=args.licence,
                                                      measured=args.measured, kernels=args.kernels or "float32")))
        return 0
    folder_only = [f for f, v in (("--licence", args.licence is not None), ("--measured", args.measured),
                                  ("--kernels", args.kernels)) if v]
    if folder_only:
        raise InvalidOptionError(f"{folder_only[0]} is for --format folder (a model folder), not {args.fmt}; "
                                 f"leave it out")

    if args.fp16 and args.int8:
        raise InvalidOptionError("--fp16 and --int8 exclude each other: a model is exported in float16 or in int8; "
                                 "leave out one of them")
    if args.int8 != (args.calibration is not None):
        raise InvalidOptionError("--int8 and --calibration DIR go together: int8 quantisation is calibrated on real "
                                 "frames" if args.int8 else "--calibration is for --int8: add --int8, or leave it out")
    print(export_report(export_model(args.checkpoint, args.fmt, args.out, calibration=args.calibration,
                                     fp16=args.fp16)))
    return 0


def kitti_submit_parser(p: argparse.ArgumentParser) -> None:
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


# --- demo ----------------------------------------------------------------------------------------------


def demo_parser(p: argparse.ArgumentParser) -> None:
    from freespace.data.synthetic.dataset import MAX_FRAMES

    p.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    p.add_argument("--num", dest="num_frames", type=bounded_int(1, MAX_FRAMES), default=60,
                   help="number of rendered frames (default 60)")
    p.add_argument("--full", action="store_true", help="the six-network protocol with three seeds (long)")
    p.add_argument("--epochs", type=bounded_int(1, MAX_EPOCHS), help="training epochs (default 12; 30 with --full)")
    p.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    """``freespace demo``: render a stereo scene, run the DS-Generator, write the pictures."""
    from freespace.demo import demo_report, run_demo

    text, ok = demo_report(run_demo(args.out, num_frames=args.num_frames, seed=args.seed, full=args.full,
                                    epochs=args.epochs), args.out)
    print(text)
    return 0 if ok else 1
