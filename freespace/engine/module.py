"""The Lightning module: a network, its losses, SGD with momentum, metrics from summed counts."""

from __future__ import annotations

import time
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch

from freespace.errors import TrainingError
from freespace.io import IGNORE_INDEX
from freespace.metrics import RoadEvaluator
from freespace.models import create_model, main_logits

__all__ = ["RoadModule", "TrainingError"]


class RoadModule(pl.LightningModule):
    """Trains ``create_model(model, **model_options)``; validation and test metrics are computed from
    confusion counts summed over the whole split (and over DDP ranks), never averaged per batch."""

    def __init__(self, model: str, model_options: dict[str, Any], lr: float, momentum: float,
                 weight_decay: float, image_size: tuple[int, int] | list[int] | None = None) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.net = create_model(model, **model_options)
        self._reset()

    def _reset(self) -> None:
        self._evaluator = RoadEvaluator()
        self._seconds = 0.0
        self._frames = 0

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=self.hparams.lr, momentum=self.hparams.momentum,
                               weight_decay=self.hparams.weight_decay)

    def on_train_epoch_start(self) -> None:
        # dropout and the like draw from a generator seeded by the epoch: a resumed run is exact
        torch.manual_seed(int(np.random.default_rng([self.trainer.current_epoch, 17]).integers(2**31)))

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        outputs = self.net(batch["image"])
        if not bool((batch["label"] != IGNORE_INDEX).any()):
            # no evaluated pixel in the whole batch (e.g. all-black KITTI ground truth, all don't care): the mean
            # over no pixel is NaN; nothing to learn, so a zero loss that still reaches every output
            zero = main_logits(outputs).sum() * 0.0
            losses = {"total": zero, "seg": zero}
        else:
            losses = self.net.loss(outputs, batch["label"], IGNORE_INDEX)
        loss = losses["total"]
        if not torch.isfinite(loss):
            raise TrainingError(f"the loss became {loss.item()} at epoch {self.current_epoch}, step {batch_idx}; "
                                f"lower --lr or check the labels")
        for k, v in losses.items():
            self.log(f"train_{'loss' if k == 'total' else k}", v.detach(), on_step=False, on_epoch=True,
                     batch_size=batch["image"].shape[0], sync_dist=True)
        return loss

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
        for k, v in self._reduce().items():
            self.log(f"val_{k}", v, sync_dist=True)  # already summed over ranks: the mean of equal values

    def on_test_epoch_end(self) -> None:
        self.test_metrics = self._reduce()
        for k, v in self.test_metrics.items():
            self.log(f"test_{k}", v, sync_dist=True)
