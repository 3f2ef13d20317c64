"""``freespace adapt``'s first step (issue 70): batch-norm statistics re-estimated on the user's frames (AdaBN,
:mod:`freespace.engine.norm_stats`), kept where an export folded them into the convolutions, and ``--norm-stats``.

A tiny Fast-SCNN (:func:`helpers.tiny_model_folder`, 32×96, trained here: real batch-norm statistics), the same
network rebuilt from its ONNX export (folded statistics: every batch norm the identity, as the published folders'
checkpoints), and generated road frames darker than the ones it was trained on.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from freespace.errors import InvalidOptionError
from freespace.io.codecs import write_image

from helpers import refused, road_frame, tiny_model_folder

pytest.importorskip("onnxruntime")

SIZE = (32, 96)
#: the frames' brightness relative to the training frames': another camera, another light
DARK = 0.45


def _dark(size: tuple[int, int], n: int, seed: int = 700) -> np.ndarray:
    return np.stack([(road_frame(size, seed + i)[0] * DARK).astype(np.uint8) for i in range(n)])


@pytest.fixture(autouse=True)
def _threads_back() -> Iterator[None]:
    """Torch's thread count as it was before each test: a test that sets it must not change later tests' numbers."""
    import torch

    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A model folder of a training run's network: real batch-norm statistics."""
    return tiny_model_folder(tmp_path_factory.mktemp("models"), SIZE)


@pytest.fixture(scope="module")
def folded(model: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same network as a published folder carries it: rebuilt from its ONNX export, which folded every batch
    norm into the convolution before it (:func:`~freespace.engine.adapt_io.checkpoint_from_onnx`)."""
    from freespace.engine.adapt_io import checkpoint_from_onnx, save_checkpoint
    from freespace.inference.export import export_model
    from freespace.inference.predictor import load_checkpoint

    tmp = tmp_path_factory.mktemp("folded")
    export_model(model / "model.ckpt", "onnx", tmp / "model.onnx")
    _, hp = load_checkpoint(model / "model.ckpt")
    folder = tmp / "tiny-folded"
    folder.mkdir()
    save_checkpoint(checkpoint_from_onnx(tmp / "model.onnx", hp["model"], hp["model_options"], SIZE), hp,
                    folder / "model.ckpt")
    return folder


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """24 dark frames of 120×48 pixels."""
    folder = tmp_path_factory.mktemp("frames") / "cam"
    folder.mkdir()
    for i, image in enumerate(_dark((48, 120), 24)):
        write_image(folder / f"f{i:03d}.png", image)
    return folder


def _norm_state(ckpt: Path) -> dict[str, np.ndarray]:
    import torch

    state = torch.load(ckpt, map_location="cpu", weights_only=True)["state_dict"]
    return {k: v.float().numpy() for k, v in state.items() if k.endswith(("running_mean", "running_var"))}


def _adapt(model: Path, frames: Path, out: Path, **kwargs) -> dict:
    import freespace

    return freespace.adapt(model, frames, out, epochs=1, threads=1, progress=False, **kwargs)


def test_reestimated_statistics_are_the_frames_own(model: Path) -> None:
    """On frames darker than the training frames every batch norm's statistics move; the first one's running mean
    is the mean of its input over the frames (the mean of the batches' means, which are nearly equal in size) and
    its running variance the mean of the batches' unbiased variances; modes and momenta are as they were."""
    import torch

    from freespace.engine.norm_stats import batch_norms, folded_norms, norm_stats_plan, reestimate_norm_stats
    from freespace.inference.predictor import load_checkpoint

    torch.set_num_threads(1)  # put back by _threads_back
    net, _ = load_checkpoint(model / "model.ckpt")
    net.eval()
    assert norm_stats_plan(net, "auto") is None and not folded_norms(net)  # a training run's: re-estimated
    norms = batch_norms(net)
    old = [(m.running_mean.clone(), m.running_var.clone()) for _, m in norms]
    seen: list[torch.Tensor] = []
    hook = norms[0][1].register_forward_pre_hook(lambda m, args: seen.append(args[0].detach().double()))
    images = _dark(SIZE, 20)
    try:
        assert reestimate_norm_stats(net, images) == 20
    finally:
        hook.remove()
    assert [len(x) for x in seen] == [7, 7, 6]  # 8 frames a pass at most, the passes nearly equal
    first = norms[0][1]
    means = torch.stack([x.mean(dim=(0, 2, 3)) for x in seen])
    variances = torch.stack([x.var(dim=(0, 2, 3), unbiased=True) for x in seen])
    assert torch.allclose(first.running_mean.double(), means.mean(0), rtol=1e-4, atol=1e-5)
    assert torch.allclose(first.running_var.double(), variances.mean(0), rtol=1e-4, atol=1e-5)
    everything = torch.cat(seen)
    assert torch.allclose(first.running_mean.double(), everything.mean(dim=(0, 2, 3)), rtol=0.02, atol=1e-3)
    assert torch.allclose(first.running_var.double(), everything.var(dim=(0, 2, 3)), rtol=0.1, atol=1e-3)
    for (_, m), (mean, var) in zip(norms, old):  # each moved to the darker frames' statistics
        assert not torch.allclose(m.running_mean, mean, atol=1e-3) or not torch.allclose(m.running_var, var, rtol=1e-2)
        assert m.momentum == 0.1
    assert not any(m.training for m in net.modules())


def test_adapt_reestimates_a_training_runs_statistics_and_records_it(model: Path, frames: Path,
                                                                      tmp_path: Path) -> None:
    """``auto`` on a training run's checkpoint: the adapted checkpoint holds the frames' statistics (the student's
    batch norms frozen at them), the summary and the card say so, with the held-out measures right after it."""
    summary = _adapt(model, frames, tmp_path / "out")
    assert summary["settings"]["norm_stats"] == "auto"
    assert summary["norm_stats"].startswith("re-estimated on ") and " frames (" in summary["norm_stats"]
    after = summary["after_norm_stats"]
    assert set(after) == {"road_share", "confidence"} and 0 <= after["road_share"] <= 1
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["norm_stats"] == summary["norm_stats"]
    card = (tmp_path / "out" / "README.md").read_text()
    assert "batch norms re-estimated, before self-training" in card and summary["norm_stats"] in card
    old, new = _norm_state(model / "model.ckpt"), _norm_state(tmp_path / "out" / "model.ckpt")
    assert old.keys() == new.keys() and all(not np.allclose(old[k], new[k]) for k in old if k.endswith("_mean"))


def test_folded_statistics_are_kept_and_the_reason_recorded(folded: Path, frames: Path, tmp_path: Path,
                                                            capsys) -> None:
    """``auto`` on a checkpoint rebuilt from ONNX keeps its identity batch norms and says why; ``frames`` on it is
    refused in one line (exit 2) before any work."""
    from freespace.engine.norm_stats import folded_norms
    from freespace.inference.predictor import load_checkpoint

    net, _ = load_checkpoint(folded / "model.ckpt")
    assert folded_norms(net)
    summary = _adapt(folded, frames, tmp_path / "out")
    assert summary["norm_stats"].startswith("kept: folded into the convolutions") and "after_norm_stats" not in summary
    assert "kept: folded into the convolutions" in (tmp_path / "out" / "README.md").read_text()
    old, new = _norm_state(folded / "model.ckpt"), _norm_state(tmp_path / "out" / "model.ckpt")
    assert all(np.array_equal(old[k], new[k]) for k in old)
    err = refused(capsys, ["adapt", "--model", str(folded), "--input", str(frames), "--out", str(tmp_path / "x"),
                           "--norm-stats", "frames", "--threads", "1", "--no-progress"], match="--norm-stats frames")
    assert "folded into the convolutions" in err and not (tmp_path / "x").exists()


def test_keep_keeps_a_training_runs_statistics(model: Path, frames: Path, tmp_path: Path) -> None:
    summary = _adapt(model, frames, tmp_path / "out", norm_stats="keep")
    assert summary["norm_stats"].startswith("kept: as asked") and "after_norm_stats" not in summary
    old, new = _norm_state(model / "model.ckpt"), _norm_state(tmp_path / "out" / "model.ckpt")
    assert all(np.array_equal(old[k], new[k]) for k in old)


@pytest.mark.parametrize("value", ["bogus", "", "AUTO"])
def test_a_bad_value_is_one_line_exit_2(value: str, model: Path, frames: Path, tmp_path: Path, capsys) -> None:
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "out"),
                     "--norm-stats", value], match="--norm-stats")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["bogus", None, 1, ["auto"]])
def test_the_library_checks_norm_stats_before_any_work(value, model: Path, frames: Path, tmp_path: Path,
                                                       monkeypatch) -> None:
    import freespace.engine.adapt as adapt_module

    def started(*args, **kwargs):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(adapt_module, "_model_folder", started)
    with pytest.raises(InvalidOptionError, match="^norm_stats must be one of auto, frames, keep, got "):
        _adapt(model, frames, tmp_path / "out", norm_stats=value)
