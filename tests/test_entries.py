"""The package's short entries: freespace.train, freespace.Predictor, freespace.adapt — lazy, documented, working."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import freespace
from freespace.errors import InvalidOptionError

ROOT = Path(__file__).resolve().parents[1]


def test_import_freespace_stays_free_of_torch() -> None:
    code = "import sys, freespace; print('torch' in sys.modules, sorted(freespace.__all__))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split(" ", 1)[0] == "False"
    for name in ("train", "Predictor", "adapt"):
        assert name in out.stdout and getattr(freespace, name).__doc__
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        freespace.nothing  # noqa: B018


def test_train_then_predict_in_python(trained: dict[str, Path], tmp_path: Path) -> None:
    """freespace.train makes the same run folder as `freespace train`; freespace.Predictor reads its checkpoint."""
    run = tmp_path / "run"
    metrics = freespace.train("synth", trained["data"], run, model="segnet", epochs=1, image_size=(64, 96),
                              batch_size=4, seed=0, progress=False)
    assert (run / "checkpoints" / "best.ckpt").is_file() and 0 <= metrics["f_score"] <= 1
    assert json.loads((run / "metrics.json").read_text())["f_score"] == pytest.approx(metrics["f_score"])
    image = np.zeros((48, 80, 3), np.uint8)
    prob = freespace.Predictor(checkpoint=run / "checkpoints" / "best.ckpt").predict([image])[0]
    assert prob.shape == (48, 80) and np.isfinite(prob).all()


def test_train_refuses_an_unknown_option_before_writing(tmp_path: Path) -> None:
    with pytest.raises(InvalidOptionError, match="unknown: epoch"):
        freespace.train("synth", tmp_path, tmp_path / "run", epoch=3)
    assert not (tmp_path / "run").exists()
