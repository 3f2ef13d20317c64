"""The training configuration: every option checked before any work, saved as the run's config.yaml."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.io import PathLike, atomic_write_text

__all__ = ["TrainConfig", "parse_size", "parse_augment", "parse_ranges", "AUGMENTS"]

AUGMENTS = ("none", "homography", "virtual")  # --augment takes one, or homography,virtual


def parse_augment(text: str) -> tuple[str, ...]:
    """``"homography,virtual"`` → ``("homography", "virtual")``; ``"none"`` → ``()``. Unknown names raise."""
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    bad = [n for n in names if n not in AUGMENTS]
    if bad or not names or ("none" in names and len(names) > 1) or len(set(names)) != len(names):
        raise InvalidOptionError(f"--augment must be none, homography, virtual or homography,virtual, got {text!r}")
    return tuple(n for n in AUGMENTS[1:] if n in names)


def parse_ranges(text: str, what: str) -> tuple[float, float, float]:
    """``"0.5,0.2,0"`` → three half-ranges ``≥ 0`` (the options of ``--augment virtual``)."""
    try:
        values = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0 <= v < 1e6 for v in values):
        raise InvalidOptionError(f"{what} must be three numbers ≥ 0 separated by commas, got {text!r}")
    return values  # type: ignore[return-value]


def parse_size(text: str | None) -> tuple[int, int] | None:
    """``"384x1248"`` → ``(384, 1248)`` (height × width); None/"auto" → None."""
    if text is None or str(text).lower() == "auto":
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", str(text))
    if not m or min(int(m.group(1)), int(m.group(2))) < 32:
        raise InvalidOptionError(f"--image-size must be HxW with both ≥ 32 (e.g. 384x1248), got {text!r}")
    return int(m.group(1)), int(m.group(2))


@dataclass
class TrainConfig:
    """Everything a training run depends on (written to ``RUN_DIR/config.yaml``)."""

    dataset: str
    root: str
    out: str
    model: str = "unet"
    preset: str = "light"
    split: str | None = None
    augment: str = "none"
    epochs: int = 50
    batch_size: int = 4
    lr: float = 0.001
    momentum: float = 0.9
    weight_decay: float = 0.0
    patience: int = 10
    image_size: tuple[int, int] | None = None
    seed: int = 0
    devices: int = 1
    num_nodes: int = 1
    strategy: str = "auto"
    workers: int = 0
    splits: str | None = None
    max_frames: int | None = None
    disparity: str = "auto"
    cache_dir: str | None = None
    tensorboard: bool = False
    # --augment virtual: half-ranges of the random pose (dx, dy, dz metres; roll, pitch, yaw degrees), probability
    virtual_shift: str = "0.5,0.2,0"
    virtual_rotate: str = "3,3,3"
    virtual_prob: float = 0.5

    def check(self) -> None:
        """Reject bad options (one-line errors), before any work."""
        from freespace.data.base import DISPARITY_MODES, list_datasets
        from freespace.models import list_models

        if self.dataset not in list_datasets():
            raise InvalidOptionError(f"unknown dataset {self.dataset!r}; choose one of {', '.join(list_datasets())}")
        if self.model not in list_models():
            raise InvalidOptionError(f"unknown model {self.model!r}; choose one of {', '.join(list_models())}")
        parse_augment(self.augment)
        parse_ranges(self.virtual_shift, "--virtual-shift DX,DY,DZ (metres)")
        parse_ranges(self.virtual_rotate, "--virtual-rotate ROLL,PITCH,YAW (degrees)")
        if not 0 <= self.virtual_prob <= 1:
            raise InvalidOptionError(f"--virtual-prob must be in [0, 1], got {self.virtual_prob}")
        if self.preset not in ("light", "paper"):
            raise InvalidOptionError(f"--preset must be light or paper, got {self.preset!r}")
        if self.disparity not in DISPARITY_MODES:
            raise InvalidOptionError(f"--disparity-source must be one of {', '.join(DISPARITY_MODES)}")
        for name in ("epochs", "batch_size", "patience", "devices", "num_nodes"):
            if getattr(self, name) < 1:
                raise InvalidOptionError(f"--{name.replace('_', '-')} must be ≥ 1, got {getattr(self, name)}")
        if self.workers < 0:
            raise InvalidOptionError("--workers must be ≥ 0")
        if not (0 < self.lr < 10) or not (0 <= self.momentum < 1) or self.weight_decay < 0:
            raise InvalidOptionError("--lr must be in (0, 10), --momentum in [0, 1), --weight-decay ≥ 0")
        if self.strategy not in ("auto", "ddp"):
            raise InvalidOptionError(f"--strategy must be auto or ddp, got {self.strategy!r}")
        if self.max_frames is not None and self.max_frames < 3:
            raise InvalidOptionError("--max-frames must be ≥ 3 (train, val and test need a frame each)")
        if self.tensorboard:
            try:
                import tensorboard  # noqa: F401
            except ImportError:
                raise InvalidOptionError("--tensorboard needs the tensorboard package: pip install tensorboard") from None
        if not Path(self.root).is_dir():
            raise InvalidOptionError(f"dataset root not found: {self.root}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["image_size"] = list(self.image_size) if self.image_size else None
        return d

    def save(self, path: PathLike) -> None:
        """Write as YAML (atomically)."""
        import yaml

        atomic_write_text(path, yaml.safe_dump(self.to_dict(), sort_keys=False))

    @classmethod
    def load(cls, path: PathLike) -> TrainConfig:
        """Read a config.yaml written by :meth:`save` (``yaml.safe_load``: runs no code)."""
        import yaml

        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise CorruptFileError(f"cannot read {path}: {str(exc).splitlines()[0]}") from None
        known = {f.name for f in fields(cls)}
        if not isinstance(data, dict) or set(data) - known:
            raise CorruptFileError(f"{path} is not a freespace training config")
        if data.get("image_size"):
            data["image_size"] = tuple(data["image_size"])
        return cls(**data)
