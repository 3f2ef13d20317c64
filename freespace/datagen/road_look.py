"""Road labels that look like road: each drive's own labels teach a road-look classifier that vetoes the geometric
road of another look (tram ballast, gravel, pavements level with the road).

The disparity labeller (:mod:`freespace.datagen.labeller`) calls road whatever lies on the road plane. A tram track's
gravel bed, a pavement without a kerb or a gravel verge lie on it too, and no disparity tells them apart; their look
does. This pass learns the road's look from the drive itself, with no human label:

1. **Features**: every frame's left image through an ImageNet EfficientNet-Lite encoder (no segmentation training),
   its stride-8 and stride-16 maps, each L2-normalised per cell and stacked: one vector per 8×8 cell.
2. **Examples**: cells the tree labels road inside a band of columns straight ahead of the car
   (:attr:`LookOptions.band`: the carriageway the car drives on, where gravel beds and pavements seldom lie) are
   road; cells it labels not road anywhere are not road (walls, cars, grass, and the gravel where the geometry saw
   its kerb). A cell counts when :attr:`LookOptions.cell_share` of its pixels carry the label.
3. **The classifier**: a logistic regression on those cells over the whole drive (both classes weighed equally,
   an L2 penalty :attr:`LookOptions.l2`): linear, so it learns a look, not the frames.
4. **The veto**: a road pixel of the tree whose cell the classifier gives a road probability under
   :attr:`LookOptions.veto` becomes don't care (its confidence 0). Road is never added and not road never changed.

Conventions: images ``H×W×3 uint8`` RGB; cells of 8×8 pixels from the top-left corner (``H // 8 × W // 8``; the last
rows and columns that fill no cell take the nearest cell's probability). torch is imported only here, not by the
labeller.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.data.label_tree import confidence_path, write_label_files
from freespace.datagen.options import LookOptions
from freespace.datagen.propagate import frame_label, read_tree_settings
from freespace.errors import DatasetError, param
from freespace.io.files import PathLike, check_outputs, check_writable, write_csv, write_json
from freespace.io.outdir import claim_folder
from freespace.labels import RoadLabel

log = logging.getLogger(__name__)

#: the stride of the cells the classifier labels, pixels
CELL = 8


def look_encoder(name: str = "efficientnet-lite0") -> Any:
    """The ImageNet EfficientNet-Lite encoder ``name`` in evaluation mode (a ``torch.nn.Module``).

    Raises:
        PretrainedWeightsError: its weights are not installed (the message says what to install).
    """
    from freespace.models.lite import LiteEncoder
    from freespace.models.weights import load_encoder_weights

    encoder = LiteEncoder(name)
    load_encoder_weights(encoder, name, "imagenet")
    return encoder.eval()


def look_features(image: np.ndarray, encoder: Any) -> np.ndarray:
    """The look of each 8×8 cell of ``image`` (``H×W×3 uint8`` RGB, H and W at least 32): ``H//8 × W//8 × C``
    float32, the encoder's stride-8 map and its stride-16 map (bilinear to stride 8), each L2-normalised per cell."""
    import torch
    import torch.nn.functional as F

    from freespace.models.lite import INPUT_MEAN, INPUT_STD

    h, w = image.shape[0] // CELL, image.shape[1] // CELL
    pad_h, pad_w = -image.shape[0] % 32, -image.shape[1] % 32
    x = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float() / 255
    x = (x - torch.tensor(INPUT_MEAN).view(1, 3, 1, 1)) / torch.tensor(INPUT_STD).view(1, 3, 1, 1)
    x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
    with torch.no_grad():
        maps = encoder(x)
        f8 = maps[3]
        f16 = F.interpolate(maps[4], size=f8.shape[2:], mode="bilinear", align_corners=False)
        cells = torch.cat([F.normalize(f8, dim=1), F.normalize(f16, dim=1)], 1)[0, :, :h, :w]
    return cells.permute(1, 2, 0).numpy().astype(np.float32)


def cell_examples(label: RoadLabel, options: LookOptions = LookOptions()) -> tuple[np.ndarray, np.ndarray]:
    """The road and not-road example cells of a frame's label (``bool H//8 × W//8`` each, see the module
    docstring: road only in :attr:`LookOptions.band`)."""
    h, w = label.shape[0] // CELL, label.shape[1] // CELL

    def share(mask: np.ndarray) -> np.ndarray:
        cropped = mask[: h * CELL, : w * CELL].astype(np.float32)
        return cropped.reshape(h, CELL, w, CELL).mean((1, 3))

    road = share(label.road & label.valid) >= options.cell_share
    not_road = share(~label.road & label.valid) >= options.cell_share
    band = np.zeros((h, w), bool)
    band[:, int(w * options.band[0]): int(np.ceil(w * options.band[1]))] = True
    return road & band, not_road


def fit_road_look(road: np.ndarray, not_road: np.ndarray, l2: float = 1e-4) -> tuple[np.ndarray, float]:
    """A logistic regression of road (``road``: ``N×C`` float32 cells) against not road (``not_road``: ``M×C``),
    both classes weighed equally; returns its weights (``C`` float64) and bias.

    Raises:
        DatasetError: a class has fewer than 10 cells (nothing to learn a look from).
    """
    import torch

    if len(road) < 10 or len(not_road) < 10:
        raise DatasetError(f"the labels give {len(road)} road and {len(not_road)} not-road cells to learn the road's "
                           f"look from (10 of each at least); label more of the drive, or leave the look check out")
    x = torch.from_numpy(np.concatenate([road, not_road])).float()
    y = torch.cat([torch.ones(len(road)), torch.zeros(len(not_road))])
    weight = torch.where(y > 0, 0.5 / len(road), 0.5 / len(not_road))
    linear = torch.nn.Linear(x.shape[1], 1)
    torch.nn.init.zeros_(linear.weight)  # a fixed start: the fit does not depend on torch's global random state
    torch.nn.init.zeros_(linear.bias)
    optimiser = torch.optim.LBFGS(linear.parameters(), max_iter=200, line_search_fn="strong_wolfe")

    def loss() -> torch.Tensor:
        optimiser.zero_grad()
        bce = torch.nn.functional.binary_cross_entropy_with_logits(linear(x)[:, 0], y, weight=weight, reduction="sum")
        value = bce + l2 * linear.weight.pow(2).sum()
        value.backward()
        return value

    optimiser.step(loss)
    return linear.weight.detach().double().numpy()[0], float(linear.bias.detach()[0])


def road_probability(features: np.ndarray, weights: np.ndarray, bias: float, shape: tuple[int, int]) -> np.ndarray:
    """The classifier's road probability of each pixel of a ``shape`` (H, W) frame from its cells' ``features``
    (``h×w×C``): ``float32 H×W``, each pixel its cell's (pixels past the last whole cell take the nearest one's)."""
    logit = features.astype(np.float64) @ weights + bias
    p = (1 / (1 + np.exp(-logit))).astype(np.float32)
    cells = np.repeat(np.repeat(p, CELL, 0), CELL, 1)
    return cv2.copyMakeBorder(cells, 0, shape[0] - cells.shape[0], 0, shape[1] - cells.shape[1], cv2.BORDER_REPLICATE)


def veto_label(label: RoadLabel, probability: np.ndarray, veto: float = 0.5) -> tuple[RoadLabel, np.ndarray]:
    """``label`` with its road pixels whose road ``probability`` (``float H×W``) is under ``veto`` made don't care;
    returns the new label and the vetoed pixels (``bool H×W``)."""
    vetoed = label.road & label.valid & (probability < veto)
    return RoadLabel(label.road & ~vetoed, label.valid & ~vetoed), vetoed


def learn_look(frames: Iterable[tuple[np.ndarray, RoadLabel]], encoder: Any, options: LookOptions = LookOptions(),
               count: int = 1) -> tuple[np.ndarray, float, dict[str, Any]]:
    """Learn one sequence's road look from its ``frames`` (``count`` of them: image ``H×W×3 uint8`` RGB, label),
    at most :attr:`LookOptions.most_examples` cells of each class (drawn with a fixed seed); returns the
    classifier's weights and bias and its row: the examples of each class and the share of each it gets right.

    Raises:
        DatasetError: fewer than 10 cells of a class.
    """
    rng = np.random.default_rng(0)
    per_frame = -(-2 * options.most_examples // max(count, 1))
    parts: tuple[list[np.ndarray], list[np.ndarray]] = ([], [])
    for image, label in frames:
        features = look_features(image, encoder)
        for mask, into in zip(cell_examples(label, options), parts):
            cells = features[mask]
            into.append(cells[rng.permutation(len(cells))[:per_frame]])
    road, not_road = (np.concatenate(p)[rng.permutation(sum(map(len, p)))[: options.most_examples]] if p
                      else np.zeros((0, 1), np.float32) for p in parts)
    weights, bias = fit_road_look(road, not_road, options.l2)
    scores = (np.concatenate([road, not_road]).astype(np.float64) @ weights + bias) > 0
    truth = np.r_[np.ones(len(road), bool), np.zeros(len(not_road), bool)]
    row = {"road_examples": len(road), "not_road_examples": len(not_road),
           "road_recall": round(float(scores[truth].mean()), 4),
           "not_road_recall": round(float((~scores[~truth]).mean()), 4)}
    return weights, bias, row


def look_veto_frames(images: list[np.ndarray], labels: list[RoadLabel], options: LookOptions = LookOptions(),
                     encoder: Any = None) -> tuple[list[RoadLabel], dict[str, Any]]:
    """The road-look veto of one sequence held in memory: ``labels`` (one per image of ``images``) with their
    road of another look made don't care, and the classifier's row (:func:`learn_look`). ``encoder``: a
    :func:`look_encoder` to reuse (default: :attr:`LookOptions.encoder`'s)."""
    options.check()
    encoder = encoder if encoder is not None else look_encoder(options.encoder)
    weights, bias, row = learn_look(zip(images, labels), encoder, options, len(images))
    vetoed = [veto_label(label, road_probability(look_features(image, encoder), weights, bias, label.shape),
                         options.veto)[0] for image, label in zip(images, labels)]
    return vetoed, row


def looks_like_road(images: np.ndarray, labels: np.ndarray, learn: np.ndarray, options: LookOptions = LookOptions(),
                    encoder: Any = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Which pixels of a sequence held in memory look like its road (``freespace adapt``'s look check).

    Args:
        images: ``N×H×W×3 uint8`` RGB frames. labels: their ``N×H×W uint8`` labels (1 road, 0 not road, 255 don't
            care). learn: the indices of the frames whose labels teach the look (:func:`learn_look`).
        options: the look's settings (:attr:`LookOptions.veto` is the road probability a pixel needs).
        encoder: a :func:`look_encoder` to reuse (default: :attr:`LookOptions.encoder`'s).

    Returns:
        ``bool N×H×W``: the road probability of each pixel's cell at or above the veto, for every frame; and the
        classifier's row (:func:`learn_look`).

    Raises:
        DatasetError: the learning frames' labels give fewer than 10 cells of a class.
    """
    options.check()
    encoder = encoder if encoder is not None else look_encoder(options.encoder)
    pairs = ((images[i], RoadLabel(labels[i] == 1, labels[i] != 255)) for i in learn)
    weights, bias, row = learn_look(pairs, encoder, options, len(learn))
    looks = np.empty(labels.shape, bool)
    for i, image in enumerate(images):
        looks[i] = road_probability(look_features(image, encoder), weights, bias, labels.shape[1:]) >= options.veto
    return looks, row


# --- a whole dataset: a label tree in, a look-checked tree out -------------------------------------------------------

#: the option that names the tree in messages
_OPTION = "look_from"


def _check_drive(dataset: StereoRoadDataset, indices: list[int], tree: Path, staging: Path, encoder: Any,
                 options: LookOptions) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Learn one drive's road look from ``tree`` and write its vetoed labels into ``staging``; the frames' rows
    and the drive's classifier row. The frames are read and encoded twice (to learn, then to veto) rather than
    held: a drive's features would take hundreds of megabytes."""

    def frames() -> Iterator[tuple[Any, np.ndarray, tuple[RoadLabel, Any, dict[str, Any], np.ndarray]]]:
        for i in indices:
            ref = dataset.frames[i]
            image = dataset.load(i, right=False, label=False, disparity=False).left
            own = frame_label(tree, ref.name, image, ref.left, option=_OPTION)
            if own is not None:
                yield ref, image, own

    weights, bias, drive = learn_look(((image, own[0]) for _, image, own in frames()), encoder, options, len(indices))
    rows = []
    for ref, image, (label, _, report, confidence) in frames():
        probability = road_probability(look_features(image, encoder), weights, bias, label.shape)
        new, vetoed = veto_label(label, probability, options.veto)
        row = {"frame": ref.name, "road_before": round(float(label.road.mean()), 4),
               "road_fraction": round(float(new.road.mean()), 4), "vetoed": round(float(vetoed.mean()), 4),
               "coverage": round(float(new.valid.mean()), 4)}
        write_label_files(new, staging / f"{ref.name}.png", np.where(vetoed, 0, confidence).astype(np.uint8),
                          confidence_path(staging, ref.name), {**report, "look": row},
                          staging / "reports" / f"{ref.name}.json")
        rows.append(row)
    return rows, drive


def look_check_dataset(dataset: StereoRoadDataset, labels: PathLike, out: PathLike, *,
                       options: LookOptions = LookOptions(), progress: bool = True) -> dict[str, Any]:
    """Veto the road of the label tree ``labels`` where the frame does not look like road (the module docstring).

    Args:
        dataset: the frames the tree labels (each scenario, a drive, learns its own look).
        labels: a tree ``freespace autolabel`` wrote for ``dataset`` (single-frame or propagated).
        out: the new label tree: ``<frame>.png`` (KITTI colours), ``confidence/`` (vetoed pixels 0), ``reports/``
            (each frame's report with its ``look`` row), ``report.csv``, ``summary.json`` and ``settings.json``
            (the tree's, with ``look`` and ``look_source_labels``): written all or nothing.
        options: :class:`LookOptions`. progress: a progress bar on a terminal.

    Returns:
        The summary: frames, seconds, each drive's classifier (examples, and the share of each class it gets
        right on them), the mean road fraction before and after and the mean vetoed share.

    Raises:
        DatasetError: the tree labels none of the frames, or a drive gives too few examples of a class.
        PretrainedWeightsError: the encoder's ImageNet weights are not installed.
    """
    from freespace.runtime.log import progress_bar

    options.check()
    tree, out = Path(labels), Path(out)
    settings = read_tree_settings(tree, dataset, option=_OPTION, done="look")
    check_writable(out, folder=True)
    check_outputs({"out": out}, {_OPTION: tree, "root": dataset.root})
    encoder = look_encoder(options.encoder)
    drives: dict[str, list[int]] = {}
    for i, f in enumerate(dataset.frames):
        drives.setdefault(f.scenario, []).append(i)
    t0, rows, classifiers = time.perf_counter(), [], {}
    with claim_folder(out, "autolabel") as folder, folder.staged() as staging:
        for scenario in progress_bar(sorted(drives), desc="look", unit="drive", enabled=progress):
            indices = sorted(drives[scenario], key=lambda i: dataset.frames[i].name)
            if not any((tree / f"{dataset.frames[i].name}.png").is_file() for i in indices):
                continue
            drive_rows, classifiers[scenario] = _check_drive(dataset, indices, tree, staging, encoder, options)
            rows += drive_rows
            log.info("look-checked %s: %d frames, %.1f%% of the pixels vetoed", scenario, len(drive_rows),
                     100 * np.mean([r["vetoed"] for r in drive_rows]))
        if not rows:
            raise DatasetError(f"{param(_OPTION)} {tree} labels none of the frames of {dataset.root}")
        summary = {"frames": len(rows), "seconds": round(time.perf_counter() - t0, 1), "drives": classifiers,
                   **{f"mean_{k}": round(float(np.mean([r[k] for r in rows])), 4)
                      for k in ("road_before", "road_fraction", "vetoed")}}
        write_csv(staging / "report.csv", list(rows[0]), rows)
        write_json(staging / "summary.json", summary)
        write_json(staging / "settings.json", {**settings, "look": options.to_dict(),
                                               "look_source_labels": str(tree.resolve())})
    return summary
