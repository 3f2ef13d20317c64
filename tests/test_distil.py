"""Distillation (``freespace train --teacher``): the teacher's term, where it applies, what a run records."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from freespace.cli import main
from freespace.engine.config import TrainConfig
from freespace.engine.init import teacher_network
from freespace.engine.module import RoadModule
from freespace.errors import InputFileError, InvalidOptionError
from freespace.labels import IGNORE_INDEX

from helpers import TRAINED_ARGS


def _module() -> RoadModule:
    torch.manual_seed(0)
    return RoadModule("fastscnn", {"width": 0.25}, lr=0.01, momentum=0.9, weight_decay=0.0, image_size=[32, 64])


def _batch(ignored_rows: int) -> dict[str, torch.Tensor]:
    torch.manual_seed(1)
    label = (torch.rand(2, 32, 64) > 0.5).long()
    label[:, :ignored_rows] = IGNORE_INDEX
    return {"image": torch.rand(2, 3, 32, 64), "label": label}


class _Constant(torch.nn.Module):
    """A teacher that says road with probability ``p`` everywhere."""

    def __init__(self, p: float) -> None:
        super().__init__()
        self.logit = torch.nn.Parameter(torch.tensor(float(torch.logit(torch.tensor(p)))))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n, _, h, w = x.shape
        return torch.stack([torch.zeros(n, h, w), self.logit.expand(n, h, w)], 1)


def _kl(module: RoadModule, batch: dict[str, torch.Tensor], p: float, where: torch.Tensor) -> float:
    module.eval()
    with torch.no_grad():
        q = torch.softmax(module.net(batch["image"]), 1)[:, 1].double()
    module.train()
    kl = p * torch.log(p / q) + (1 - p) * torch.log((1 - p) / (1 - q))
    return float(kl[where].mean())


def _distil_term(module: RoadModule, batch: dict[str, torch.Tensor]) -> float:
    module.eval()  # the same forward pass as the reference's (batch norms as evaluated)
    with torch.no_grad():
        logits = module.net(batch["image"])
        return float(module._distil(logits, batch["image"], batch["label"] == IGNORE_INDEX))


def test_the_term_is_the_kl_divergence_from_the_teachers_probabilities_over_its_pixels() -> None:
    module, batch = _module(), _batch(ignored_rows=8)
    module.attach_teacher(_Constant(0.8), weight=2.0, pixels="all")
    every = torch.ones(2, 32, 64, dtype=torch.bool)
    assert _distil_term(module, batch) == pytest.approx(_kl(module, batch, 0.8, every), rel=1e-4)
    module.attach_teacher(_Constant(0.8), weight=2.0, pixels="ignored")
    ignored = batch["label"] == IGNORE_INDEX
    assert _distil_term(module, batch) == pytest.approx(_kl(module, batch, 0.8, ignored), rel=1e-4)
    assert _distil_term(module, _batch(ignored_rows=0)) == 0.0  # no don't-care pixel: nothing to teach there


def test_a_step_adds_the_weighted_term_trains_the_network_and_leaves_the_teacher_alone() -> None:
    module, batch = _module(), _batch(ignored_rows=8)
    torch.manual_seed(2)
    with torch.no_grad():
        plain = float(module.net.loss(module.net(batch["image"]), batch["label"])["total"])
    teacher = _Constant(0.9)
    module.attach_teacher(teacher, weight=3.0)
    module.log = lambda *a, **k: None  # no trainer here
    torch.manual_seed(2)
    loss = module.training_step(batch, 0)
    assert float(loss.detach()) > plain + 0.1  # the teacher's term, weighted, on top of the labels'
    loss.backward()
    assert all(p.grad is not None for p in module.net.parameters() if p.requires_grad)
    assert teacher.logit.grad is None and not teacher.training
    assert not any(k.startswith("_teacher") or "logit" in k for k in module.state_dict())  # never saved


def test_an_all_dont_care_batch_still_learns_the_teacher() -> None:
    module, batch = _module(), _batch(ignored_rows=32)
    module.attach_teacher(_Constant(0.9), pixels="ignored")
    module.log = lambda *a, **k: None
    loss = module.training_step(batch, 0)
    assert float(loss.detach()) > 0.0 and torch.isfinite(loss)


def test_options_without_a_teacher_and_a_missing_teacher_are_refused(tmp_path: Path) -> None:
    with pytest.raises(InvalidOptionError, match="give teacher too"):
        TrainConfig(dataset="kitti", root=str(tmp_path), out=str(tmp_path / "run"), teacher_weight=2.0)
    with pytest.raises(InvalidOptionError, match="teacher_pixels"):
        TrainConfig(dataset="kitti", root=str(tmp_path), out=str(tmp_path / "run"), teacher=str(tmp_path),
                    teacher_pixels="some")
    with pytest.raises(InputFileError, match="teacher not found"):
        teacher_network(tmp_path / "nothing.ckpt")


def test_cli_refuses_a_bad_teacher_in_one_line_and_writes_nothing(trained: dict[str, Path], tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    junk = tmp_path / "junk.ckpt"
    junk.write_bytes(b"not a checkpoint")
    for teacher, words in ((tmp_path / "none.ckpt", "--teacher not found"), (junk, "junk.ckpt"),
                           (tmp_path, "without model.ckpt")):
        out = tmp_path / "run"
        code = main(["train", "--dataset", "synth", "--root", str(trained["data"]), *TRAINED_ARGS, "--out", str(out),
                     "--teacher", str(teacher)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and words in err[0], err
        assert not out.exists()


def test_a_run_with_a_teacher_records_it_and_refuses_to_resume_with_another(
        trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    teacher = shutil.copy(trained["ckpt"], tmp_path / "teacher.ckpt")
    out = tmp_path / "run"
    args = ["train", "--dataset", "synth", "--root", str(trained["data"]), *TRAINED_ARGS, "--out", str(out),
            "--teacher", str(teacher), "--teacher-weight", "0.5", "--teacher-pixels", "all"]
    assert main(args) == 0
    assert TrainConfig.load(out / "config.yaml").teacher == str(Path(teacher).resolve())
    assert "teacher" in json.loads((out / "inputs.json").read_text())
    student = torch.load(out / "checkpoints" / "best.ckpt", weights_only=True)
    assert not any(k.startswith("teacher") for k in student["hyper_parameters"])  # predicting needs no teacher
    shutil.copy(out / "checkpoints" / "best.ckpt", teacher)  # another model in its place
    assert main([*args, "--epochs", "2", "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "teacher.ckpt" in err and "resuming would train one run on two" in err, err
