"""A training run: ``freespace train``.

The run folder holds ``config.yaml`` (resolved options), ``splits/`` (train/val/test lists),
``generated/`` (DS-Generator views, with ``augment="homography"``), ``metrics.csv`` (one row per epoch,
numbered from 1 as ``best_epoch`` in metrics.json),
``checkpoints/best.ckpt`` and ``checkpoints/last.ckpt`` (written atomically) and, at the end,
``metrics.json`` (test split: accuracy, precision, recall, f_score, iou, max_f, ap as fractions, seconds
per frame; ``record``: the package commit, data root and torch version that finished the run, never compared
on resume). ``resume=True`` continues from ``last.ckpt``; with the same seed on a CPU the result is the
same as an uninterrupted run's: data order, augmentation and dropout are drawn from (seed, epoch).
"""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import logging
import os
import time
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint
from lightning.pytorch.plugins.io import TorchCheckpointIO

from freespace.data.label_tree import changed_inputs
from freespace.data.torch_dataset import RoadSegmentationDataset
from freespace.engine.config import TrainConfig
from freespace.engine.data import EpochSampler, is_rank_zero, loader_context, prepare_data
from freespace.engine.init import read_init, resolve_init, teacher_network
from freespace.engine.record import content_hashes, run_record
from freespace.errors import CorruptFileError, FreespaceError, InvalidOptionError, Terminated, TrainingError, param
from freespace.inference.predictor import check_weights, checkpoint_state_dict, read_checkpoint_file
from freespace.io.files import atomic_write_bytes, write_csv, write_json
from freespace.io.outdir import claim_folder
from freespace.models.registry import warn_if_below_intact_size
from freespace.runtime.log import on_terminal, quiet_lightning

log = logging.getLogger(__name__)

__all__ = ["run_training"]

CSV_FIELDS = ["epoch", "train_loss", "val_accuracy", "val_precision", "val_recall", "val_f_score", "val_iou",
              "val_max_f", "val_ap", "val_f_window", "lr", "seconds"]


def monitored(val_window: int) -> str:
    """The metric that early stopping and the best checkpoint follow: the epoch's validation F-score, or
    with ``val_window`` > 1 its mean over the last ``val_window`` epochs."""
    return "val_f_score" if val_window == 1 else "val_f_window"


#: the number of a run's first epoch in its record (metrics.csv's ``epoch``, metrics.json's ``best_epoch``,
#: index.json, results.md): epochs are counted as people count them. metrics.json says so (``first_epoch``);
#: files written before hold 0-based numbers and are read right (:func:`read_epoch_rows`, and reproduce's tables)
FIRST_EPOCH = 1


def read_epoch_rows(path: Path) -> list[dict[str, str]]:
    """The rows of a run's ``metrics.csv``, ``epoch`` numbered from :data:`FIRST_EPOCH`: a file of an older
    version numbered them from 0 (its first row says which: the rows start at the run's first epoch)."""
    rows = list(csv.DictReader(path.open()))
    if rows and rows[0].get("epoch") == "0":
        rows = [{**r, "epoch": str(int(r["epoch"]) + FIRST_EPOCH)} for r in rows]
    return rows


class EpochCSV(pl.Callback):
    """``metrics.csv`` of the run folder ``run_dir``: one row per finished epoch (``epoch`` numbered from
    :data:`FIRST_EPOCH`), rewritten atomically (kept across resumes)."""

    def __init__(self, run_dir: Path) -> None:
        self.path = run_dir / "metrics.csv"
        self.t0 = time.perf_counter()

    def on_train_epoch_start(self, trainer, module) -> None:
        self.t0 = time.perf_counter()

    def on_train_epoch_end(self, trainer, module) -> None:
        if not trainer.is_global_zero:
            return
        m = trainer.callback_metrics
        rows = []
        number = trainer.current_epoch + FIRST_EPOCH  # Lightning counts from 0
        if self.path.is_file():
            rows = [r for r in read_epoch_rows(self.path) if int(r["epoch"]) < number]
        row = {"epoch": number, "lr": trainer.optimizers[0].param_groups[0]["lr"],
               "seconds": round(time.perf_counter() - self.t0, 3)}
        row.update({k: f"{float(m[k]):.6f}" for k in CSV_FIELDS if k in m})
        write_csv(self.path, CSV_FIELDS, rows + [row])
        if not on_terminal() or not trainer.progress_bar_callback:  # a log gets one line per epoch
            log.info("epoch %d/%d  loss %s  val F %s  IoU %s  (%.1f s)", number,
                     trainer.max_epochs, row.get("train_loss", "—"), row.get("val_f_score", "—"),
                     row.get("val_iou", "—"), row["seconds"])


class LabelledPixels(pl.Callback):
    """Fails the run at the end of a training epoch in which no sample had a labelled pixel (every pixel don't
    care): its loss is exactly 0 and the network learns nothing, which must not end as a finished run. Counted
    over all processes."""

    def __init__(self) -> None:
        self.count: torch.Tensor | int = 0

    def on_train_epoch_start(self, trainer, module) -> None:
        self.count = 0

    def on_train_batch_start(self, trainer, module, batch, batch_idx) -> None:
        from freespace.labels import IGNORE_INDEX

        self.count = self.count + (batch["label"] != IGNORE_INDEX).sum()  # on the device: no sync per step

    def on_train_epoch_end(self, trainer, module) -> None:
        count = torch.as_tensor(self.count, device=module.device).float()  # only compared with 0
        total = trainer.strategy.reduce(count, reduce_op="sum")
        if float(total) == 0:
            raise TrainingError(f"no training sample of epoch {trainer.current_epoch + FIRST_EPOCH} has a labelled "
                                f"pixel (every pixel is don't care), so the loss is 0 and nothing is learnt; check "
                                f"the training labels (the dataset's, or {param('labels')})")


def _callbacks(run_dir: Path, patience: int, val_window: int,
               min_delta: float = 0.0) -> tuple[list[pl.Callback], ModelCheckpoint]:
    monitor = monitored(val_window)
    ckpt = ModelCheckpoint(dirpath=run_dir / "checkpoints", filename="best", monitor=monitor, mode="max",
                           save_top_k=1, enable_version_counter=False)
    # last.ckpt after every epoch, by a callback of its own: Lightning >= 2.5 writes `save_last`'s file only on
    # the epochs that write the best one too, so a resume would go back to the best epoch and train the epochs
    # after it again (listed after `ckpt`, it saves that callback's state of this epoch)
    last = ModelCheckpoint(dirpath=run_dir / "checkpoints", filename="last", save_top_k=1,
                           enable_version_counter=False)
    stop = _EarlyStopping(monitor=monitor, mode="max", patience=patience, min_delta=min_delta, check_finite=True,
                          val_window=val_window)
    return [LabelledPixels(), ckpt, last, stop, EpochCSV(run_dir)], ckpt


class _EarlyStopping(EarlyStopping):
    """Early stopping whose state (best score, epochs without improvement) is replayed from the run's validation
    history when training starts, never read from a resumed checkpoint; the patience is the run's config.

    The state is a function of the history of validation F-scores (which the module keeps in its checkpoint),
    the window and the least improvement: a run resumed with a larger patience goes on exactly as a run started
    with it would, and so does a run resumed from a checkpoint that holds no state of this callback (one written
    before its name changed: Lightning then silently started counting anew, which let three cells of the
    converged run stop at other epochs than the protocol's)."""

    def __init__(self, *args: Any, val_window: int = 1, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.val_window = val_window

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Nothing to read: :meth:`on_train_start` replays the state."""

    def on_train_start(self, trainer: pl.Trainer, module: pl.LightningModule) -> None:
        self.best_score = -torch.tensor(torch.inf)
        self.wait_count = 0
        history = module.val_f_history
        for i in range(len(history)):  # as the module logged it: the window's mean, a tensor of the default dtype
            current = float(np.mean(history[max(0, i + 1 - self.val_window):i + 1]))
            self._evaluate_stopping_criteria(torch.tensor(current, dtype=torch.get_default_dtype()))


#: what a run writes into its folder, as :mod:`freespace.io.outdir` entries (removed when a plain rerun takes
#: over a start that never checkpointed)
RUN_ENTRIES = ("config.yaml", "inputs.json", "splits/", "generated/", "metrics.csv", "metrics.json", "checkpoints/",
               "tensorboard/")

#: the run's record of what it read, by content (:func:`freespace.engine.record.content_hashes`)
INPUTS = "inputs.json"


def read_inputs(run_dir: Path) -> dict[str, Any]:
    """A run's ``inputs.json`` (what it read, by content hash), or ``{}`` for a run of an older version or a
    damaged file."""
    import json

    try:
        found = json.loads((run_dir / INPUTS).read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    return found if isinstance(found, dict) else {}


class RunCheckpointIO(TorchCheckpointIO):
    """Checkpoints of the run folder ``run_dir``.

    Saving goes to a temporary file that is renamed, so a killed run keeps a valid ``last.ckpt``.
    Loading uses ``torch.load(weights_only=True)`` (a checkpoint runs no code), refuses a corrupt or
    crafted file with one line, and points every path that the checkpoint callback stored back into
    this run folder: a copied or moved run, or a crafted file, never reads or deletes files elsewhere.
    With ``module``, weights and optimizer state that do not fit it are refused too.
    """

    def __init__(self, run_dir: Path, module: torch.nn.Module | None = None) -> None:
        super().__init__()
        self.run_dir = run_dir
        self.module = module

    def save_checkpoint(self, checkpoint: dict[str, Any], path, storage_options=None) -> None:
        buf = _io.BytesIO()
        torch.save(checkpoint, buf)
        atomic_write_bytes(path, buf.getvalue())

    def load_checkpoint(self, path, map_location=None, weights_only=None) -> dict[str, Any]:
        checkpoint = read_checkpoint_file(path)
        _check_training_state(checkpoint, path)
        if self.module is not None:
            _check_fits(checkpoint, self.module, path)
        for state in (checkpoint.get("callbacks") or {}).values():
            if isinstance(state, dict) and "dirpath" in state:
                _confine_paths(state, Path(os.path.realpath(self.run_dir / "checkpoints")))  # as Lightning keeps it
        return checkpoint


#: the parts of a checkpoint that Lightning restores on resume, and their types
_RESTORED = {"loops": dict, "callbacks": dict, "optimizer_states": list, "lr_schedulers": list, "epoch": int,
             "global_step": int}


def _check_training_state(checkpoint: Any, path: Path) -> None:
    """Refuse a checkpoint whose weights, or the parts of it that Lightning restores, are not of the types
    Lightning expects (a damaged or crafted file would otherwise end in a traceback deep inside it)."""
    checkpoint_state_dict(checkpoint, path)
    bad = [k for k, kind in _RESTORED.items() if k in checkpoint and not isinstance(checkpoint[k], kind)]
    if not bad:
        bad = [f"{part}[{k!r}]" for part in ("callbacks", "loops") for k, v in checkpoint.get(part, {}).items()
               if not isinstance(v, dict)]
        bad += [f"optimizer_states[{i}]" for i, o in enumerate(checkpoint.get("optimizer_states", []))
                if not (isinstance(o, dict) and isinstance(o.get("state"), dict)
                        and isinstance(o.get("param_groups"), list)
                        and all(isinstance(g, dict) for g in o["param_groups"]))]
        bad += [f"lr_schedulers[{i}]" for i, o in enumerate(checkpoint.get("lr_schedulers", []))
                if not isinstance(o, dict)]
    if bad:
        raise CorruptFileError(f"{path} is not a freespace training checkpoint, or is damaged ({bad[0]} is not what "
                               f"Lightning saves); it was not loaded")


def _check_fits(checkpoint: dict[str, Any], module: torch.nn.Module, path: Path) -> None:
    """Refuse a checkpoint whose weights or optimizer state do not fit ``module`` (the run's network)."""
    check_weights(module, checkpoint["state_dict"], path)
    params = list(module.parameters())
    for opt in checkpoint.get("optimizer_states") or []:
        for i, state in opt["state"].items():
            fits = isinstance(i, int) and 0 <= i < len(params) and isinstance(state, dict) and all(
                tuple(t.shape) == tuple(params[i].shape) for t in state.values()
                if isinstance(t, torch.Tensor) and t.dim() > 0)  # momentum buffers; a step count is a scalar
            if not fits:
                raise CorruptFileError(f"{path}: its optimizer state does not fit the run's network (parameter {i!r}); "
                                       f"it was not loaded")


def _confine_paths(state: dict[str, Any], folder: Path) -> None:
    """Rewrite a ModelCheckpoint state so that every file it names is ``folder/<its own file name>``."""
    def inside(path: Any) -> str:
        name = Path(str(path)).name if path else ""
        return str(folder / name) if name in ("best.ckpt", "last.ckpt") else ""

    state["dirpath"] = str(folder)
    for key in ("best_model_path", "kth_best_model_path", "last_model_path"):
        if key in state:
            state[key] = inside(state[key])
    if isinstance(state.get("best_k_models"), dict):
        state["best_k_models"] = {inside(k): v for k, v in state["best_k_models"].items() if inside(k)}


def train(dataset: str | None = None, root: str | os.PathLike | None = None, out: str | os.PathLike | None = None, *,
          resume: bool = False, progress: bool = True, **options: Any) -> dict[str, Any]:
    """Train a network in one call (``freespace.train``): ``TrainConfig(dataset=…, root=…, out=…, **options)`` —
    every option of ``freespace train`` by its parameter name, as typed values — then :func:`run_training`. A
    labelled folder instead of a dataset: ``images=…, labels=…, label_format=…`` (or ``labels_like=…``), and
    ``init=`` a model folder to fine-tune.

    Returns the test metrics (fractions; also in ``out/metrics.json``). Raises
    :class:`~freespace.errors.InvalidOptionError` for an unknown or bad option, before anything is written.

    Example (not run here: it trains)::

        metrics = freespace.train("kitti", "data/syn", "runs/unet-ha", model="unet", augment=("homography",),
                                  epochs=1, image_size=(96, 128))
        metrics = freespace.train(out="runs/mine", images="frames", labels="masks", labels_like="cityscapes",
                                  init="models/real-road-fast")
    """
    if out is None:
        raise InvalidOptionError(f"freespace.train needs {param('out')}, the run folder")
    unknown = sorted(set(options) - {f.name for f in dataclasses.fields(TrainConfig)})
    if unknown:
        raise InvalidOptionError(f"freespace.train takes TrainConfig's options; unknown: {', '.join(unknown)}")
    config = TrainConfig(dataset=dataset, root=os.fspath(root) if root is not None else None, out=os.fspath(out),
                         **options)
    return run_training(config, resume=resume, progress=progress)


def run_training(config: TrainConfig, resume: bool = False, progress: bool = True) -> dict[str, Any]:
    """Train, validate each epoch, stop early on the validation F-score, test the best checkpoint.

    ``config`` is checked first (:meth:`TrainConfig.check`, before anything is written). ``resume``
    continues the run in ``config.out`` from its last checkpoint, with the run's options (``epochs`` and
    ``patience`` may grow: a run that early stopping ended goes on as if started with the larger values, and
    its ``metrics.json`` is removed until the new end).

    Returns the test metrics (also written to ``RUN_DIR/metrics.json``).
    """
    deterministic = torch.are_deterministic_algorithms_enabled()
    try:
        return _run(config, resume, progress)
    finally:  # Lightning's deterministic mode is process-wide: give the caller its own setting back (only when
        # changed: the call imports torch._inductor, which fails after Ctrl-C cut an import of Lightning short)
        if torch.are_deterministic_algorithms_enabled() != deterministic:
            torch.use_deterministic_algorithms(deterministic)


def _run(config: TrainConfig, resume: bool, progress: bool) -> dict[str, Any]:
    config = resolve_init(config)  # the init's network and size, before a resumed run compares its options
    saved = Path(config.out) / "config.yaml"
    if resume and saved.is_file():  # before the checks: an option changed is named, not what it breaks (weights...)
        _refuse_changed(config, TrainConfig.load(saved))
    config.check()  # before anything is written
    run_dir = Path(config.out)
    if not is_rank_zero():  # DDP children re-run the command inside the folder their launcher holds
        return _train(config, resume, progress)
    with claim_folder(run_dir, "train", entries=RUN_ENTRIES) as folder:
        last = run_dir / "checkpoints" / "last.ckpt"
        inputs = content_hashes(config)  # before any work: a changed weights file or label tree is refused
        if resume:
            config = _check_resume(config, run_dir, last)
            changed = changed_inputs(read_inputs(run_dir), inputs)
            if changed:
                raise InvalidOptionError(f"{run_dir} started from other contents of {changed[0]}; resuming would "
                                         f"train one run on two; restore the files, or start a new run (another "
                                         f"{param('out')})")
            (run_dir / "metrics.json").unlink(missing_ok=True)  # the run is unfinished again until its new end
        elif (run_dir / "config.yaml").is_file():
            if last.is_file():
                raise InvalidOptionError(f"{run_dir} already holds a run; add {param('resume')} to continue it or "
                                         f"choose another {param('out')}")
            _check_restart(run_dir)
            folder.forget(RUN_ENTRIES)
            folder.record(RUN_ENTRIES)  # the new run writes them again: still this command's files
        if not resume:  # (a resumed run of an older version records nothing it cannot vouch for)
            write_json(run_dir / INPUTS, inputs)
        try:
            return _train(config, resume, progress)
        except FreespaceError as exc:  # a user's mistake (a corrupt frame) before the first checkpoint: no output
            if exc.exit_code == 2 and not last.is_file():
                folder.forget(RUN_ENTRIES)
            raise


#: the files a run writes in its subfolders whose names it knows (a file there that is none of them is the user's)
_OWN_FILES = {"checkpoints": ("best.ckpt", "last.ckpt"), "splits": ("train.txt", "val.txt", "test.txt")}


def _check_restart(run_dir: Path) -> None:
    """Before a run without ``checkpoints/last.ckpt`` is started again in ``run_dir`` (its files deleted):
    refuse when ``checkpoints/`` or ``splits/`` holds a file the run does not write (named), and say whether
    the run had trained (its checkpoints then were removed) or never reached a checkpoint."""
    for sub, names in _OWN_FILES.items():
        folder = run_dir / sub
        for path in sorted(folder.rglob("*")) if folder.is_dir() and not folder.is_symlink() else []:
            rel = path.relative_to(folder)
            ours = len(rel.parts) == 1 and any(  # one of its files, or what a killed write of one left
                rel.name == n or rel.name.startswith(f".{n}.") and rel.name.endswith(".tmp") for n in names)
            if not ours:
                raise InvalidOptionError(f"{run_dir} holds a run without checkpoints/last.ckpt, and "
                                         f"{sub}/{rel.as_posix()}, which freespace train did not write; starting the "
                                         f"run again deletes {sub}/: move that file away, or choose another "
                                         f"{param('out')}")
    try:
        with (run_dir / "metrics.csv").open(newline="") as f:
            epochs = sum(1 for _ in csv.DictReader(f))
    except (OSError, ValueError, csv.Error):
        epochs = 0
    if epochs or (run_dir / "checkpoints" / "best.ckpt").is_file():
        log.warning("%s holds a run that trained %d epoch(s) but whose checkpoints/last.ckpt is gone, so it cannot "
                    "be resumed: training it again from the start (put last.ckpt back to continue it instead)",
                    run_dir, epochs)
    else:
        log.info("%s holds a run that never reached a checkpoint: starting it again", run_dir)


def _check_resume(config: TrainConfig, run_dir: Path, last: Path) -> TrainConfig:
    """Refuse to resume a folder with no checkpoint, a damaged one, or other options than the run's (its
    config.yaml, in the spelling of any version); return ``config`` with the run's image size when it asks
    for :data:`~freespace.engine.config.FIRST_FRAME_SIZE` (resolved when the run started)."""
    if (run_dir / "config.yaml").is_file() and not last.is_file():
        raise InvalidOptionError(f"{run_dir} never reached its first checkpoint, so there is nothing to resume; "
                                 f"run the same command without {param('resume')} to start it again")
    if not (run_dir / "config.yaml").is_file():
        raise InvalidOptionError(f"{param('resume')} needs a run folder with config.yaml and checkpoints/last.ckpt; "
                                 f"{run_dir} has none")
    saved = TrainConfig.load(run_dir / "config.yaml")
    resumed = RunCheckpointIO(run_dir).load_checkpoint(last)  # refuse a damaged or crafted file before any work
    config = config.with_size(saved.image_size)
    _refuse_changed(config, saved)
    from freespace.models import create_model  # the run's network, named as in RoadModule: before any work

    _check_fits(resumed, torch.nn.ModuleDict({"net": create_model(config.model, **config.model_options())}), last)
    return config


def _refuse_changed(config: TrainConfig, saved: TrainConfig) -> None:
    """Refuse to resume the run started with ``saved`` (its config.yaml) with other options, naming each."""
    changed = config.diff(saved)[0]
    if changed:
        raise InvalidOptionError(f"{param('resume')} with other options than the run's ({'; '.join(changed)}); "
                                 f"resume with the same options (only {param('epochs')} and {param('patience')} "
                                 f"may grow)")


def _train(config: TrainConfig, resume: bool, progress: bool) -> dict[str, Any]:
    quiet_lightning()

    from freespace.engine.module import RoadModule

    run_dir = Path(config.out)
    last = run_dir / "checkpoints" / "last.ckpt"
    pl.seed_everything(config.seed, workers=True, verbose=False)
    data = prepare_data(config, run_dir)
    config = config.with_size(data["size"])  # resolved
    if is_rank_zero():
        config.save(run_dir / "config.yaml")
    ds, size = data["dataset"], tuple(data["size"])
    warn_if_below_intact_size(config.model, config.preset, size)
    photometric = config.photometric_strength if config.photometric else False
    train, val, test = (RoadSegmentationDataset(ds, data[k], size=size, affine=k == "train", seed=config.seed,
                                                cache=True, virtual=data["virtual"] if k == "train" else None,
                                                flip=config.flip and k == "train",
                                                photometric=photometric if k == "train" else False,
                                                zoom=config.zoom if k == "train" else 0.0, resize=config.resize,
                                                crop_top=config.crop_top if k == "train" else 0.0)
                        for k in ("train", "val", "test"))

    def loader(frames: RoadSegmentationDataset, shuffle: bool) -> torch.utils.data.DataLoader:
        return torch.utils.data.DataLoader(frames, batch_size=config.batch_size if shuffle else 1,
                                           sampler=EpochSampler(len(frames), config.seed, shuffle),
                                           num_workers=config.workers, persistent_workers=config.workers > 0,
                                           multiprocessing_context=loader_context() if config.workers > 0 else None)

    torch.manual_seed(config.seed)  # the initial weights depend on the seed only, whatever the data preparation drew
    module = RoadModule(config.model, config.model_options(), config.lr, config.momentum, config.weight_decay,
                        image_size=list(size), seed=config.seed, val_window=config.val_window,
                        encoder_weights=config.encoder_weights, freeze=frozen_part(config), resize=config.resize,
                        lr_schedule=config.lr_schedule)
    if config.teacher is not None:  # outside the checkpoint: attached again when the run goes on
        module.attach_teacher(teacher_network(config.teacher), config.teacher_weight, config.teacher_pixels)
    if config.init is not None and not resume:  # every weight from the init (a resumed run has its own)
        module.net.load_state_dict(read_init(config.init).state)
    elif not resume:  # what a network fits from the labels (e.g. DUpsampling's W) comes back with the checkpoint
        # from the training frames themselves (the first items; views and duplicates follow), so that every
        # variant of the protocol fits it from the same labels
        module.net.prepare(train[i]["label"] for i in range(data["frames"]))
    callbacks, ckpt = _callbacks(run_dir, config.patience, config.val_window, config.min_delta)
    trainer = pl.Trainer(
        accelerator="auto" if config.devices == 1 else "cpu" if not torch.cuda.is_available() else "auto",
        devices=config.devices, num_nodes=config.num_nodes, strategy="ddp" if config.strategy == "ddp" else "auto",
        max_epochs=config.epochs, callbacks=callbacks, plugins=[RunCheckpointIO(run_dir, module)],
        logger=_logger(config, run_dir),
        default_root_dir=str(run_dir), num_sanity_val_steps=0, deterministic=deterministic_mode(),
        enable_progress_bar=progress and on_terminal(), enable_model_summary=False, use_distributed_sampler=False,
        log_every_n_steps=1)
    _interruptible(trainer.fit, module, loader(train, True), loader(val, False),
                   ckpt_path=str(last) if resume else None)
    best = run_dir / "checkpoints" / "best.ckpt"  # this folder's, whatever a resumed checkpoint recorded
    best = best if best.is_file() else last
    _interruptible(trainer.test, module, loader(test, False), ckpt_path=str(best), verbose=False)
    metrics = {**module.test_metrics, "best_epoch": _best_epoch(run_dir, monitored(config.val_window)),
               "first_epoch": FIRST_EPOCH, "epochs_run": trainer.current_epoch,
               "frames": {k: len(data[k]) for k in ("train", "val", "test")}, "image_size": list(size),
               "checkpoint": best.relative_to(run_dir).as_posix()}
    if data["labelled"] is not None:
        metrics["labelled_folder"] = data["labelled"].record(config)
    if config.init is not None:
        metrics["init"] = {"path": str(read_init(config.init).path), "freeze": frozen_part(config)}
    metrics["record"] = run_record(config.root or config.images)  # the commit, data root and torch of the run
    if trainer.is_global_zero:
        write_json(run_dir / "metrics.json", metrics)
    return metrics


def frozen_part(config: TrainConfig) -> str:
    """What keeps its starting values in ``config``'s run: its ``freeze``, with ``auto`` resolved (``norm`` when
    the run starts from an ``init``, else ``none``)."""
    if config.freeze != "auto":
        return config.freeze
    return "norm" if config.init is not None else "none"


def deterministic_mode() -> bool | str:
    """Lightning's ``deterministic`` for this process's run: ``True`` (every operation's deterministic
    kernel, or an error) without a GPU; ``"warn"`` with one, where some kernels have no deterministic CUDA
    version (the 2-D cross-entropy loss's forward, ``nll_loss2d``, which every network trains with): those
    warn and run, the others (cuBLAS too: Lightning sets ``CUBLAS_WORKSPACE_CONFIG``) stay deterministic.
    With ``True`` a GPU run would stop at its first step."""
    return "warn" if torch.cuda.is_available() else True


def _interruptible(step: Any, *args: Any, **kwargs: Any) -> Any:
    """``trainer.fit`` or ``trainer.test`` (``step``), where Ctrl-C stays a :class:`KeyboardInterrupt`.

    Lightning catches Ctrl-C, tears the run down, ignores Ctrl-C from then on and calls ``sys.exit(1)``;
    here that exit becomes the :class:`KeyboardInterrupt` again (the command line then says "interrupted",
    exit code 130) and Ctrl-C is handled as before. Other exceptions, ``SIGTERM``'s
    :class:`~freespace.errors.Terminated` included, Lightning passes on as they are; and where Lightning noticed a
    ``SIGTERM`` whose :class:`~freespace.errors.Terminated` was swallowed (raised where Python ignores exceptions,
    e.g. a ``__del__``), its exit is :class:`~freespace.errors.Terminated` too. An error of Lightning's own
    tear-down after Ctrl-C or ``SIGTERM`` (it fails when the signal came while a loader's workers started:
    "call `iter(combined_loader)` first") does not hide the signal: the command still ends as interrupted or
    terminated.
    """
    import signal

    trainer = step.__self__
    handler = signal.getsignal(signal.SIGINT)
    try:
        return step(*args, **kwargs)
    except SystemExit:
        if trainer.received_sigterm:
            raise Terminated() from None
        if trainer.interrupted:
            raise KeyboardInterrupt from None
        raise
    except Exception as exc:
        context: BaseException | None = exc
        while context is not None and not isinstance(context, (Terminated, KeyboardInterrupt)):
            context = context.__context__
        if context is not None:
            raise type(context)() from None
        raise
    finally:
        if handler is not None and signal.getsignal(signal.SIGINT) is not handler:
            signal.signal(signal.SIGINT, handler)


def _logger(config: TrainConfig, run_dir: Path):
    """TensorBoard logs in ``RUN_DIR/tensorboard`` when asked for (metrics.csv is always written)."""
    if not config.tensorboard:
        return False
    from lightning.pytorch.loggers import TensorBoardLogger

    return TensorBoardLogger(str(run_dir), name="tensorboard", version="")


def _best_epoch(run_dir: Path, monitor: str) -> int | None:
    """The epoch (numbered from :data:`FIRST_EPOCH`) whose ``monitor`` in ``metrics.csv`` is highest (the first
    of equals)."""
    path = run_dir / "metrics.csv"
    if not path.is_file():
        return None
    rows = read_epoch_rows(path)
    scored = [r for r in rows if r.get(monitor)]
    return int(max(scored, key=lambda r: float(r[monitor]))["epoch"]) if scored else None
