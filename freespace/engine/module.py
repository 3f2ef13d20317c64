"""The Lightning module: a network, its losses, SGD with momentum (a constant or poly rate), metrics from summed
counts."""

from __future__ import annotations

import time
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch

from freespace.engine.config import LR_SCHEDULES, TEACHER_PIXELS
from freespace.errors import TrainingError, param
from freespace.evaluation.metrics import RoadEvaluator
from freespace.labels import IGNORE_INDEX
from freespace.models import create_model, main_logits

__all__ = ["RoadModule", "TrainingError", "epoch_seed", "POLY_POWER"]

#: the exponent of the ``poly`` learning-rate decay (DeepLab's, and most segmentation codebases')
POLY_POWER = 0.9


def epoch_seed(seed: int, epoch: int) -> int:
    """The torch seed of one training epoch (dropout and the like) of a run with ``seed``."""
    return int(np.random.default_rng([seed, epoch, 17]).integers(2**31))


class RoadModule(pl.LightningModule):
    """Trains ``create_model(model, **model_options)``; validation and test metrics are computed from
    confusion counts summed over the whole split (and over DDP ranks), never averaged per batch.

    ``encoder_weights`` (``"imagenet"`` or a file) initialise the encoder; they are kept out of
    ``model_options``, so that a checkpoint rebuilds the network without them and loads its own tensors.
    """

    def __init__(self, model: str, model_options: dict[str, Any], lr: float, momentum: float,
                 weight_decay: float, image_size: tuple[int, int] | list[int] | None = None, seed: int = 0,
                 val_window: int = 1, encoder_weights: str | None = None, freeze: str = "none",
                 resize: str = "stretch", lr_schedule: str = "constant") -> None:
        """``seed``: the run's seed, from which dropout draws (with the epoch); ``val_window``: the epochs
        over which ``val_f_window`` (the early-stopping and checkpoint criterion when > 1) averages the
        validation F-score; ``encoder_weights``: the encoder's initial weights ("imagenet" or a file; a
        checkpoint rebuilds the network without them and loads its own tensors); ``freeze``: what keeps its
        starting values while training: ``none``, ``norm`` (every batch norm stays in eval mode: its running
        statistics are the start's, its scale and shift still learn) or ``encoder`` (``norm``, and the weights of
        the network's ``encoder`` are fixed); ``resize``: how frames were fitted to ``image_size``
        (:mod:`freespace.io.frame_fit`), kept in the checkpoint so that prediction fits them the same way;
        ``lr_schedule``: ``constant`` or ``poly`` (:meth:`configure_optimizers`)."""
        super().__init__()
        self.save_hyperparameters()
        weights = {"encoder_weights": encoder_weights} if encoder_weights is not None else {}
        self.net = create_model(model, **model_options, **weights)
        if freeze not in ("none", "norm", "encoder"):
            raise ValueError(f"freeze must be none, norm or encoder, got {freeze!r}")
        if lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {LR_SCHEDULES}, got {lr_schedule!r}")
        encoder = getattr(self.net, "encoder", None) if freeze == "encoder" else None
        if encoder is not None:
            encoder.requires_grad_(False)
        self._val_f: list[float] = []  # each epoch's validation F-score (kept in checkpoints)
        self._teacher: tuple[torch.nn.Module, float, str] | None = None  # attach_teacher's
        self._reset()

    def attach_teacher(self, teacher: torch.nn.Module, weight: float = 1.0, pixels: str = "all") -> None:
        """Distillation: from now on each training step also runs ``teacher`` (a network in eval mode that maps
        the ``N×3×H×W`` batch to ``N×2×H×W`` logits, e.g. :func:`~freespace.engine.init.teacher_network`'s) on
        the batch as the network sees it and adds ``weight`` × the mean KL divergence of the network's class
        probabilities from the teacher's, over ``pixels``: ``all`` or ``ignored`` (only the don't-care ones of
        the labels); the step logs it as ``train_distil``. The teacher is kept outside the module's weights: it
        is neither trained nor saved in checkpoints (a resumed run attaches it again)."""
        if pixels not in TEACHER_PIXELS:
            raise ValueError(f"pixels must be one of {TEACHER_PIXELS}, got {pixels!r}")
        teacher = teacher.eval().requires_grad_(False).to(memory_format=torch.channels_last)  # as batches come
        self._teacher = (teacher, float(weight), pixels)

    def _reset(self) -> None:
        self._evaluator = RoadEvaluator()
        self._seconds = 0.0
        self._frames = 0

    def _frozen_norms(self) -> list[torch.nn.Module]:
        if self.hparams.get("freeze", "none") == "none":
            return []
        return [m for m in self.net.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]

    def on_train_batch_start(self, batch: dict[str, Any], batch_idx: int) -> None:
        # frozen batch norms (freeze) in eval mode at every step: Lightning switches modules to training mode
        # submodule by submodule (and restores recorded modes after validation), past any train() override
        for m in self._frozen_norms():
            m.eval()

    def configure_optimizers(self):
        """SGD with momentum over the trainable weights; with ``lr_schedule`` ``poly`` the rate after step ``s`` is
        ``lr · (1 − s / S)^0.9``, ``S`` the steps of all the trainer's ``max_epochs`` (zero at the last), stepped
        after every batch (DeepLab's decay; an early stop leaves it where it was)."""
        sgd = torch.optim.SGD([p for p in self.parameters() if p.requires_grad], lr=self.hparams.lr,
                              momentum=self.hparams.momentum, weight_decay=self.hparams.weight_decay)
        if self.hparams.get("lr_schedule", "constant") == "constant":  # and checkpoints made before the option
            return sgd
        poly = torch.optim.lr_scheduler.PolynomialLR(sgd, total_iters=max(int(self.trainer.estimated_stepping_batches),
                                                                          1), power=POLY_POWER)
        return {"optimizer": sgd, "lr_scheduler": {"scheduler": poly, "interval": "step"}}

    def on_fit_start(self) -> None:
        # channels-last (NHWC) tensors take the faster convolution kernels: an epoch costs less on a CPU (BENCHMARKS.md,
        # "Epoch cost before and after a speed-up") for the same maths (equal in float64; dropout masks are drawn in
        # memory order, so they differ from NCHW's draws). Batches follow in on_after_batch_transfer.
        self.net.to(memory_format=torch.channels_last)

    def on_test_start(self) -> None:
        self.on_fit_start()

    def on_after_batch_transfer(self, batch: dict[str, Any], dataloader_idx: int) -> dict[str, Any]:
        return {**batch, "image": batch["image"].contiguous(memory_format=torch.channels_last)}

    def on_train_epoch_start(self) -> None:
        # dropout and the like draw from a generator seeded by the run's seed and the epoch: a resumed run is exact
        torch.manual_seed(epoch_seed(self.hparams.seed, self.trainer.current_epoch))

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        outputs = self.net(batch["image"])
        ignored = batch["label"] == IGNORE_INDEX
        if bool(ignored.all()):
            # no evaluated pixel in the whole batch (e.g. all-black KITTI ground truth, all don't care): the mean
            # over no pixel is NaN; nothing to learn, so a zero loss that still reaches every output
            zero = main_logits(outputs).sum() * 0.0
            losses = {"total": zero, "seg": zero}
        else:
            losses = self.net.loss(outputs, batch["label"], IGNORE_INDEX)
        if self._teacher is not None:
            distil = self._distil(main_logits(outputs), batch["image"], ignored)
            losses = {**losses, "total": losses["total"] + self._teacher[1] * distil, "distil": distil}
        loss = losses["total"]
        if not torch.isfinite(loss):
            raise TrainingError(f"the loss became {loss.item()} at epoch {self.current_epoch}, step {batch_idx}; "
                                f"lower {param('lr')} or check the labels")
        for k, v in losses.items():
            self.log(f"train_{'loss' if k == 'total' else k}", v.detach(), on_step=False, on_epoch=True,
                     batch_size=batch["image"].shape[0], sync_dist=True)
        return loss

    def _distil(self, logits: torch.Tensor, image: torch.Tensor, ignored: torch.Tensor) -> torch.Tensor:
        """The mean KL divergence ``KL(teacher ‖ network)`` of the two classes' probabilities over the teacher's
        pixels (``N×H×W`` ``ignored`` when it teaches only those; zero when there is none in the batch)."""
        teacher, _, pixels = self._teacher
        if next(teacher.parameters()).device != image.device:  # once: after Lightning moved the module
            teacher.to(image.device)
        with torch.no_grad():
            target = torch.softmax(main_logits(teacher(image)).float(), 1)
        kl = (target * (torch.log(target.clamp_min(1e-8)) - torch.log_softmax(logits.float(), 1))).sum(1)
        if pixels == "all":
            return kl.mean()
        return (kl * ignored).sum() / ignored.sum().clamp_min(1)

    def _accumulate(self, batch: dict[str, Any]) -> None:
        t0 = time.perf_counter()
        logits = main_logits(self.net(batch["image"]))
        self._seconds += time.perf_counter() - t0
        self._frames += batch["image"].shape[0]
        label = batch["label"]
        prob = torch.softmax(logits.float(), 1)[:, 1]
        self._evaluator.process(prob.cpu().numpy(), (label == 1).cpu().numpy(), (label != IGNORE_INDEX).cpu().numpy())

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        self._accumulate(batch)

    def test_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        self._accumulate(batch)

    def on_validation_epoch_start(self) -> None:
        self._reset()

    def on_test_epoch_start(self) -> None:
        self._reset()

    def _reduce(self) -> dict[str, float]:
        """Sum the split's counts over ranks, then compute the metrics once."""
        packed = np.concatenate([self._evaluator.to_vector(), [self._seconds, self._frames]])
        packed = self.trainer.strategy.reduce(torch.from_numpy(packed).to(self.device), reduce_op="sum").cpu().numpy()
        scores = RoadEvaluator.from_vector(packed[:RoadEvaluator.VECTOR_SIZE]).evaluate()
        metrics = {k: scores[k] for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap")}
        metrics["seconds_per_frame"] = float(packed[-2] / max(packed[-1], 1))
        return metrics

    def on_validation_epoch_end(self) -> None:
        metrics = self._reduce()
        for k, v in metrics.items():
            self.log(f"val_{k}", v, sync_dist=True)  # already summed over ranks: the mean of equal values
        if not self.trainer.sanity_checking:
            self._val_f.append(float(metrics["f_score"]))
        window = self._val_f[-self.hparams.val_window:] or [float(metrics["f_score"])]
        self.log("val_f_window", float(np.mean(window)), sync_dist=True)

    @property
    def val_f_history(self) -> list[float]:
        """The validation F-score (a fraction) of each epoch trained so far, resumed ones included."""
        return list(self._val_f)

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        checkpoint["val_f_history"] = self.val_f_history

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        history = checkpoint.get("val_f_history", [])
        self._val_f = [float(x) for x in history] if isinstance(history, list) else []

    def on_test_epoch_end(self) -> None:
        self.test_metrics = self._reduce()
        for k, v in self.test_metrics.items():
            self.log(f"test_{k}", v, sync_dist=True)
