"""freespace: drivable road (collision-free space) from stereo images — road model, DS-Generator, training, deployment.

The command line parses options, calls the library and reports. This package is the command line: here the table of
commands, the parser and ``main``; each command's options beside its handler (``cmd_<command>``) in the module of
its job (:mod:`~freespace.cli.data`: generate, autolabel, synth, datasets; :mod:`~freespace.cli.training`:
train, evaluate, evaluate-kitti, adapt, reproduce; :mod:`~freespace.cli.deploy`: predict, export, kitti-submit,
demo); what they share in :mod:`~freespace.cli.shared`. The options of ``train`` and ``reproduce`` are generated
from :class:`~freespace.engine.config.TrainConfig`'s fields (:mod:`~freespace.cli.config_options`: the flag of a
field is ``--name-with-dashes``, or the one :data:`CONFIG_FLAGS` names).

Only the parser of the command that runs is filled in, and heavy modules are imported inside each command, so that
``freespace generate`` starts fast and never imports torch. Every :class:`~freespace.errors.FreespaceError` ends the
command with a one-line message on stderr and exit code 2; a dataset run with failed frames exits with 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

from freespace import __version__
from freespace.cli.config_options import CONFIG_FLAGS, config_file_options
from freespace.cli.data import autolabel_parser, datasets_parser, generate_parser, synth_parser
from freespace.cli.deploy import demo_parser, export_parser, kitti_submit_parser, predict_parser
from freespace.cli.shared import Parser
from freespace.cli.shared import flags_of as _flags
from freespace.cli.training import (
    REPRODUCE_OPTIONS,
    adapt_parser,
    evaluate_kitti_parser,
    evaluate_parser,
    reproduce_parser,
    train_parser,
)
from freespace.errors import FreespaceError, InvalidOptionError, Terminated

__all__ = ["COMMANDS", "CONFIG_FLAGS", "REPRODUCE_OPTIONS", "build_parser", "main"]

# --- the commands ---------------------------------------------------------------------------------------

# name: (one-line help, description, parser builder); each builder sets its handler as ``func``
COMMANDS: dict[str, tuple[str, str, Callable[..., None]]] = {
    "generate": ("fit the road model and write the DS-Generator image(s)",
                 "Fit the road disparity model to the road pixels of a stereo pair and warp the target (right) "
                 "image into the reference (left) view with the road homography; for one pair or every labelled "
                 "frame of a dataset. With --virtual: the reference image and its label from another camera pose, "
                 "through the road plane (no right image).", generate_parser),
    "autolabel": ("road labels from disparity alone (no people): one left image or a whole dataset",
                  "Fit the road disparity model to the whole frame and label the pixels that agree with it (KITTI "
                  "colours: road magenta, non-road red, don't care black where the evidence is weak), with an 8-bit "
                  "confidence; for one left image (from --disparity, or SGBM with --target) or every frame of a "
                  "dataset, as a label tree that `train --labels` reads.", autolabel_parser),
    "synth": ("render the built-in stereo road dataset (KITTI road layout)",
              "Render stereo road scenes (left, right, exact disparity, road label, calibration) as a KITTI road "
              "tree. Frame i depends only on the seed and i.", synth_parser),
    "datasets": ("inspect datasets", "Inspect and check datasets.", datasets_parser),
    "train": ("train a network (optionally with the homography or virtual-view augmentation)",
              "Train a segmentation network on a dataset's train split, validate each epoch, stop early on the "
              "validation F-score and test the best checkpoint. The run folder holds config.yaml, splits/, "
              "metrics.csv, checkpoints/ and metrics.json.", train_parser),
    "evaluate": ("evaluate a model on labelled frames: metrics with intervals, per-frame scores, overlays",
                 "Evaluate a checkpoint or an ONNX model on a subset (train, val, test or all) of a dataset's "
                 "on-disk split, or on a labelled folder of real frames (KITTI ground truth, binary masks, class "
                 "ids, palette colours); writes metrics.json (pooled scores, frame-level bootstrap intervals), "
                 "per_frame.csv, overlays/ (TP green, FN red, FP blue) and pr_curve.png.",
                 evaluate_parser),
    "evaluate-kitti": ("evaluate KITTI-format confidence maps like the KITTI road devkit",
                       "Evaluate 8-bit road confidence PNGs against KITTI road ground truth as the official devkit "
                       "does (256 thresholds, don't-care excluded, counts summed per category, MaxF, 11-point AP, "
                       "PRE/REC/FPR/FNR at MaxF); perspective view, or the benchmark's bird's-eye view with --bev "
                       "--calib.", evaluate_kitti_parser),
    "predict": ("road confidence maps (KITTI 8-bit PNG) and overlays for images, or an overlaid video",
                "Predict every frame of an image, a folder, a glob or a video with a checkpoint or an ONNX model; "
                "writes <name>.png (8-bit road confidence, input size; 255 = sure road), overlays/<name>.png and "
                "summary.json (runtime per frame), or with --out OUT.mp4 the overlaid video.", predict_parser),
    "export": ("export a checkpoint to ONNX or TorchScript (validated)",
               "Export a checkpoint to ONNX (dynamic batch, height and width) or TorchScript; the export is "
               "checked against PyTorch and the max abs difference printed.", export_parser),
    "adapt": ("adapt a published road model to your camera's unlabelled frames",
              "Self-train a published model folder (its checkpoint) on unlabelled frames: a slowly moving teacher "
              "labels the pixels it is sure of, the student learns them on strongly augmented views; a collapse "
              "guard refuses a model that drifts to all road or no road. Writes a new model folder: model.onnx "
              "(float16), model.ckpt, README.md (the card), before_after.jpg and the run's record.", adapt_parser),
    "kitti-submit": ("KITTI road testing predictions in the benchmark's BEV format",
                     "Predict data_road/testing and write bird's-eye-view confidence maps <cat>_road_<id>.png "
                     "(800×400, x −10…10 m, z 6…46 m) made with each frame's calibration as the devkit does, and "
                     "submission.zip.", kitti_submit_parser),
    "reproduce": ("the paper's experiments: every network with and without HA; tables, figures",
                  "Train every chosen network on the original and on the augmented training set (same seeds, "
                  "budget, early stopping; --variants adds the virtual-view arms HV-X and HAV-X), test them, and "
                  "write results.md/.csv (mean ± std over seeds, each variant's gain over X), "
                  "figures and an index of the runs. Finished runs are skipped when run again.", reproduce_parser),
    "demo": ("run the built-in demo end to end",
             "Render stereo road scenes, run the DS-Generator on them and write the results.", demo_parser),
}


def build_parser(commands: Collection[str] | None = None,
                 config: Mapping[str, Any] | None = None) -> argparse.ArgumentParser:
    """The argument parser of the ``freespace`` command, with the options of ``commands`` (default: all;
    the others are listed but take no options). ``config``: option values read from ``train --config``."""
    parser = Parser(prog="freespace", description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--version", action="version", version=f"freespace {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log messages")
    parser.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (summary, description, build) in COMMANDS.items():
        p = sub.add_parser(name, help=summary, description=description)
        if commands is None or name in commands:
            if build is train_parser:
                train_parser(p, config)  # with the values of --config
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``freespace`` console script; returns the exit code.

    Ctrl-C ends a command with "interrupted" and exit code 130, ``SIGTERM`` (SLURM's time limit, ``kill``)
    with "terminated" and 143; both after the command's clean-ups (``finally`` blocks) have run.
    """
    from freespace.io.files import shown_path, writing_as
    from freespace.runtime.log import setup_logging
    from freespace.runtime.signals import missing_extra, sigterm_raises

    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)  # the global options take no value
    parser: argparse.ArgumentParser | None = None
    with sigterm_raises():  # SIGTERM raises Terminated until the message is out
        try:
            config = config_file_options(argv) if command == "train" else None
            parser = build_parser({command} if command else (), config)
            args, extra = parser.parse_known_args(argv)
            if extra:
                _refuse_extra_arguments(parser, extra, command)
            setup_logging(-1 if args.quiet else args.verbose)
            with writing_as(command or "freespace"):  # the mark of the files it writes (freespace.io.files)
                return int(args.func(args))
        except FreespaceError as exc:  # one line, even where a file name holds a newline (shown escaped)
            flags = _flags(parser or build_parser({command} if command else ()), argv)
            text = shown_path(exc.render(lambda name: flags.get(name, name)))  # a name of any bytes: \xNN
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
