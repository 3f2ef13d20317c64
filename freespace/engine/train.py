"""A training run: ``freespace train``.

The run folder holds ``config.yaml`` (resolved options), ``splits/`` (train/val/test lists),
``generated/`` (DS-Generator views, with ``--augment homography``), ``metrics.csv`` (one row per epoch),
``checkpoints/best.ckpt`` and ``checkpoints/last.ckpt`` (written atomically) and, at the end,
``metrics.json`` (test split: accuracy, precision, recall, f_score, iou, max_f, ap as fractions, seconds
per frame). ``resume=True`` continues from ``last.ckpt``; with the same seed on a CPU the result is the
same as an uninterrupted run's: data order, augmentation and dropout are drawn from (seed, epoch).
"""

from __future__ import annotations

import csv
import io as _io
import logging
import time
from pathlib import Path
from typing import Any

import torch

from freespace.engine.config import TrainConfig
from freespace.engine.data import EpochSampler, RoadFrames, is_rank_zero, prepare_data
from freespace.errors import InvalidOptionError
from freespace.io import atomic_write_bytes, atomic_write_text, write_json
from freespace.models.registry import warn_if_below_intact_size

log = logging.getLogger(__name__)

__all__ = ["run_training"]

CSV_FIELDS = ["epoch", "train_loss", "val_accuracy", "val_precision", "val_recall", "val_f_score", "val_iou",
              "val_max_f", "val_ap", "lr", "seconds"]


def _callbacks(run_dir: Path, patience: int):
    import lightning.pytorch as pl
    from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint

    class EpochCSV(pl.Callback):
        """``metrics.csv``: one row per finished epoch, rewritten atomically (kept across resumes)."""

        def __init__(self) -> None:
            self.path = run_dir / "metrics.csv"
            self.t0 = time.perf_counter()

        def on_train_epoch_start(self, trainer, module) -> None:
            self.t0 = time.perf_counter()

        def on_train_epoch_end(self, trainer, module) -> None:
            if not trainer.is_global_zero:
                return
            m = trainer.callback_metrics
            rows = []
            if self.path.is_file():
                rows = [r for r in csv.DictReader(self.path.open()) if int(r["epoch"]) < trainer.current_epoch]
            row = {"epoch": trainer.current_epoch, "lr": trainer.optimizers[0].param_groups[0]["lr"],
                   "seconds": round(time.perf_counter() - self.t0, 3)}
            row.update({k: f"{float(m[k]):.6f}" for k in CSV_FIELDS if k in m})
            buf = _io.StringIO()
            writer = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows + [row])
            atomic_write_text(self.path, buf.getvalue())

    ckpt = ModelCheckpoint(dirpath=run_dir / "checkpoints", filename="best", monitor="val_f_score", mode="max",
                           save_top_k=1, save_last=True, enable_version_counter=False)
    stop = EarlyStopping(monitor="val_f_score", mode="max", patience=patience, check_finite=True)
    return [ckpt, stop, EpochCSV()], ckpt


def _atomic_io():
    from lightning.pytorch.plugins.io import TorchCheckpointIO

    class AtomicCheckpointIO(TorchCheckpointIO):
        """Checkpoints go to a temporary file and are renamed: a killed run keeps a valid last.ckpt."""

        def save_checkpoint(self, checkpoint: dict[str, Any], path, storage_options=None) -> None:
            buf = _io.BytesIO()
            torch.save(checkpoint, buf)
            atomic_write_bytes(path, buf.getvalue())

    return AtomicCheckpointIO()


def run_training(config: TrainConfig, resume: bool = False, progress: bool = True) -> dict[str, Any]:
    """Train, validate each epoch, stop early on the validation F-score, test the best checkpoint.

    Returns the test metrics (also written to ``RUN_DIR/metrics.json``).
    """
    deterministic = torch.are_deterministic_algorithms_enabled()
    try:
        return _run(config, resume, progress)
    finally:  # Lightning's deterministic mode is process-wide: give the caller its own setting back
        torch.use_deterministic_algorithms(deterministic)


def _run(config: TrainConfig, resume: bool, progress: bool) -> dict[str, Any]:
    import lightning.pytorch as pl

    from freespace.engine.module import RoadModule

    run_dir = Path(config.out)
    last = run_dir / "checkpoints" / "last.ckpt"
    if resume:
        if not (run_dir / "config.yaml").is_file() or not last.is_file():
            raise InvalidOptionError(f"--resume needs a run folder with config.yaml and checkpoints/last.ckpt; "
                                     f"{run_dir} has none")
        saved = TrainConfig.load(run_dir / "config.yaml")
        if config.image_size is None:
            config.image_size = saved.image_size  # "auto" was resolved when the run started
        changed = [k for k, v in saved.to_dict().items()
                   if k not in ("epochs", "out", "devices", "num_nodes", "strategy", "workers", "tensorboard")
                   and config.to_dict()[k] != v]
        if changed:
            raise InvalidOptionError(f"--resume with other options than the run's ({', '.join(changed)}); "
                                     f"resume with the same options (only --epochs may grow)")
    elif (run_dir / "config.yaml").is_file() and is_rank_zero():  # DDP children re-run the command: skip
        raise InvalidOptionError(f"{run_dir} already holds a run; add --resume to continue it or choose another --out")
    config.check()
    pl.seed_everything(config.seed, workers=True, verbose=False)
    data = prepare_data(config, run_dir)
    if is_rank_zero():
        config.image_size = tuple(data["size"])  # resolved
        config.save(run_dir / "config.yaml")
    ds, size = data["dataset"], tuple(data["size"])
    warn_if_below_intact_size(config.model, config.preset, size)
    train = RoadFrames(ds, data["train"], size, augment=True, seed=config.seed)
    val = RoadFrames(ds, data["val"], size, augment=False, seed=config.seed)
    test = RoadFrames(ds, data["test"], size, augment=False, seed=config.seed)

    def loader(frames: RoadFrames, shuffle: bool) -> torch.utils.data.DataLoader:
        return torch.utils.data.DataLoader(frames, batch_size=config.batch_size if shuffle else 1,
                                           sampler=EpochSampler(len(frames), config.seed, shuffle),
                                           num_workers=config.workers, persistent_workers=config.workers > 0)

    module = RoadModule(config.model, {"preset": config.preset}, config.lr, config.momentum, config.weight_decay,
                        image_size=list(size))
    if not resume:  # what a network fits from the labels (e.g. DUpsampling's W) comes back with the checkpoint
        module.net.prepare(train[i]["label"] for i in range(len(data["train"])))
    callbacks, ckpt = _callbacks(run_dir, config.patience)
    trainer = pl.Trainer(
        accelerator="auto" if config.devices == 1 else "cpu" if not torch.cuda.is_available() else "auto",
        devices=config.devices, num_nodes=config.num_nodes, strategy="ddp" if config.strategy == "ddp" else "auto",
        max_epochs=config.epochs, callbacks=callbacks, plugins=[_atomic_io()], logger=_logger(config, run_dir),
        default_root_dir=str(run_dir), num_sanity_val_steps=0, deterministic=True,
        enable_progress_bar=progress, enable_model_summary=False, use_distributed_sampler=False,
        log_every_n_steps=1)
    trainer.fit(module, loader(train, True), loader(val, False), ckpt_path=str(last) if resume else None)
    best = ckpt.best_model_path or str(last)
    trainer.test(module, loader(test, False), ckpt_path=best, verbose=False)
    metrics = {**module.test_metrics, "best_epoch": _best_epoch(run_dir), "epochs_run": trainer.current_epoch,
               "frames": {k: len(data[k]) for k in ("train", "val", "test")}, "image_size": list(size),
               "checkpoint": str(Path(best).relative_to(run_dir)) if Path(best).is_relative_to(run_dir) else best}
    if trainer.is_global_zero:
        write_json(run_dir / "metrics.json", metrics)
    return metrics


def _logger(config: TrainConfig, run_dir: Path):
    """TensorBoard logs in ``RUN_DIR/tensorboard`` when asked for (metrics.csv is always written)."""
    if not config.tensorboard:
        return False
    from lightning.pytorch.loggers import TensorBoardLogger

    return TensorBoardLogger(str(run_dir), name="tensorboard", version="")


def _best_epoch(run_dir: Path) -> int | None:
    path = run_dir / "metrics.csv"
    if not path.is_file():
        return None
    rows = list(csv.DictReader(path.open()))
    scored = [r for r in rows if r.get("val_f_score")]
    return int(max(scored, key=lambda r: float(r["val_f_score"]))["epoch"]) if scored else None
