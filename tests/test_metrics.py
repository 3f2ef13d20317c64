"""Metrics: hand-computed cases, the KITTI devkit's published algorithm as a fixture, per-category
summing, don't-care handling, degenerate cases; the evaluator (batches, DDP-style sums); `freespace
evaluate-kitti`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import ShapeMismatchError
from freespace.evaluation.metrics import (
    Counts,
    KittiCounts,
    RoadEvaluator,
    confusion_counts,
    kitti_counts,
    kitti_scores,
    to_confidence,
)
from freespace.io.codecs import road_label_to_kitti, write_image
from freespace.labels import RoadLabel


def devkit_reference(images: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> dict[str, float]:
    """The devkit's algorithm written out independently: float probabilities, histograms over the
    threshold edges (-inf, 0, 1/255, …, 1, inf), counts summed over images, then MaxF/AP/PRE/REC/FPR/FNR."""
    thres = np.arange(256) / 255.0
    edges = np.concatenate(([-np.inf], thres, [np.inf]))
    FN = np.zeros(256)
    FP = np.zeros(256)
    P = N = 0
    for conf, road, valid in images:
        prob = conf.astype(np.float64) / 255.0
        fn_hist = np.histogram(prob[road & valid], bins=edges)[0]
        FN += np.cumsum(fn_hist)[:256]
        fp_hist = np.histogram(prob[~road & valid], bins=edges)[0]
        FP += np.flipud(np.cumsum(np.flipud(fp_hist)))[1:257]
        P += np.count_nonzero(road & valid)
        N += np.count_nonzero(~road & valid)
    TP = P - FN
    recall = TP / float(P)
    precision = TP / (TP + FP + 1e-10)
    sel = TP > 0
    recall, precision = recall[sel], precision[sel]
    ap = np.mean([precision[np.where(recall >= r)].max() for r in np.arange(0, 1.1, 0.1)])
    F = 2 * precision * recall / (precision + recall + 1e-10)
    k = F.argmax()
    i = np.flatnonzero(sel)[k]
    tp, fp, fn = (np.float32(x) for x in (TP[i], FP[i], FN[i]))
    return {"max_f": F[k], "ap": ap, "pre": tp / (tp + fp), "rec": tp / np.float32(P),
            "fpr": fp / np.float32(N), "fnr": fn / np.float32(P)}


def _random_image(rng: np.random.Generator, shape=(40, 60)):
    road = np.zeros(shape, bool)
    road[shape[0] // 2:, 10:50] = True
    noise = rng.normal(0, 60, shape)
    conf = np.clip(np.where(road, 170, 70) + noise, 0, 255).astype(np.uint8)
    valid = rng.random(shape) > 0.1
    return conf, road, valid


def test_counts_by_hand() -> None:
    pred = np.array([[1, 1, 0, 0], [1, 0, 0, 1]], bool)
    road = np.array([[1, 0, 1, 0], [1, 0, 0, 0]], bool)
    valid = np.array([[1, 1, 1, 1], [1, 1, 1, 0]], bool)
    c = confusion_counts(pred, road, valid)
    assert (c.tp, c.fp, c.fn, c.tn) == (2, 1, 1, 3)
    m = c.metrics()
    assert m["precision"] == pytest.approx(2 / 3) and m["recall"] == pytest.approx(2 / 3)
    assert m["f_score"] == pytest.approx(2 / 3) and m["iou"] == pytest.approx(0.5)
    assert m["accuracy"] == pytest.approx(5 / 7)
    # summed, not averaged
    assert (c + Counts(0, 0, 4, 0)).metrics()["recall"] == pytest.approx(2 / 7)


def test_degenerate_counts_are_defined() -> None:
    road = np.zeros((4, 4), bool)
    nothing = confusion_counts(np.zeros((4, 4), bool), road).metrics()
    assert nothing == {"accuracy": 1.0, "precision": 1.0, "recall": 1.0, "f_score": 1.0, "iou": 1.0}
    all_road = confusion_counts(np.ones((4, 4), bool), road).metrics()
    assert all_road["precision"] == 0.0 and all_road["f_score"] == 0.0 and all_road["iou"] == 0.0
    assert not any(np.isnan(v) for v in all_road.values())


def test_kitti_counts_by_hand() -> None:
    conf = np.array([[0, 100, 200, 255]], np.uint8)
    road = np.array([[False, True, True, False]])
    k = kitti_counts(conf, road)
    assert k.pos == 2 and k.neg == 2
    assert k.fn[0] == 0 and k.fn[100] == 0 and k.fn[101] == 1 and k.fn[201] == 2
    assert k.fp[0] == 2 and k.fp[1] == 1 and k.fp[255] == 1
    s = kitti_scores(k)
    # threshold 1..100 keeps both road pixels and the 255 one: P = 2/3, R = 1
    assert s["max_f"] == pytest.approx(0.8, abs=1e-9) and s["threshold"] == pytest.approx(1 / 255)
    assert s["pre"] == pytest.approx(2 / 3) and s["rec"] == 1.0 and s["fpr"] == 0.5 and s["fnr"] == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kitti_scores_match_the_devkit_algorithm(seed: int) -> None:
    rng = np.random.default_rng(seed)
    images = [_random_image(rng) for _ in range(4)]
    total = KittiCounts()
    for conf, road, valid in images:
        total = total + kitti_counts(conf, road, valid)
    ours = kitti_scores(total)
    ref = devkit_reference(images)
    for key in ("max_f", "ap", "pre", "rec", "fpr", "fnr"):
        assert ours[key] == pytest.approx(float(ref[key]), abs=1e-12), key


def test_per_category_summing_is_not_per_image_averaging() -> None:
    rng = np.random.default_rng(5)
    a, b = _random_image(rng), _random_image(rng, (20, 60))
    summed = kitti_scores(kitti_counts(*a) + kitti_counts(*b))["max_f"]
    averaged = (kitti_scores(kitti_counts(*a))["max_f"] + kitti_scores(kitti_counts(*b))["max_f"]) / 2
    assert summed == pytest.approx(float(devkit_reference([a, b])["max_f"]), abs=1e-12)
    assert summed != pytest.approx(averaged, abs=1e-6)


def test_dont_care_pixels_leave_the_counts() -> None:
    conf = np.full((3, 3), 255, np.uint8)
    road = np.zeros((3, 3), bool)
    road[0] = True
    valid = np.zeros((3, 3), bool)
    valid[0] = True
    k = kitti_counts(conf, road, valid)
    assert k.pos == 3 and k.neg == 0 and kitti_scores(k)["max_f"] == pytest.approx(1.0)


def test_kitti_degenerate_cases() -> None:
    no_road = kitti_counts(np.full((5, 5), 200, np.uint8), np.zeros((5, 5), bool))
    s = kitti_scores(no_road)
    assert s["max_f"] == 0.0 and s["fnr"] == 0.0 and s["fpr"] == 1.0
    constant = kitti_scores(kitti_counts(np.zeros((5, 5), np.uint8), np.eye(5, dtype=bool)))
    assert constant["rec"] == 1.0 and constant["pre"] == pytest.approx(0.2) and not np.isnan(constant["ap"])


def test_to_confidence_rounds_half_to_even_and_clips() -> None:
    prob = np.array([0.0, 0.5, 1.0, 1.2, -0.1, 1 / 510, 3 / 510, 0.25], np.float32)
    assert to_confidence(prob).tolist() == [0, 128, 255, 255, 0, 0, 2, 64]
    assert to_confidence(prob).dtype == np.uint8


def _random_prob(rng: np.random.Generator, shape=(30, 40)):
    road = np.zeros(shape, bool)
    road[shape[0] // 2:, 5:30] = True
    prob = np.clip(np.where(road, 0.7, 0.3) + rng.normal(0, 0.3, shape), 0, 1).astype(np.float32)
    return prob, road, rng.random(shape) > 0.1


def test_evaluator_sums_counts_over_images_batches_and_processes() -> None:
    rng = np.random.default_rng(11)
    images = [_random_prob(rng) for _ in range(6)]
    ev = RoadEvaluator()
    for prob, road, valid in images:
        ev.process(prob, road, valid)
    counts, kitti = Counts(), KittiCounts()
    for prob, road, valid in images:
        counts = counts + confusion_counts(prob >= 0.5, road, valid)
        kitti = kitti + kitti_counts(to_confidence(prob), road, valid)
    m = ev.evaluate()
    assert ev.images == 6 and m["images"] == 6
    assert ev.counts == counts and {k: m[k] for k in counts.metrics()} == counts.metrics()
    assert {k: m[k] for k in kitti_scores(kitti)} == kitti_scores(kitti)
    assert 0.6 < m["f_score"] < 0.95 and 0.6 < m["max_f"] < 0.95  # noisy but informative maps
    # one batch (N×H×W) counts the same as image by image
    batch = RoadEvaluator()
    batch.process(*(np.stack(x) for x in zip(*images)))
    assert batch.images == 6 and np.array_equal(batch.to_vector(), ev.to_vector())
    # two "ranks" each see half the images; their summed state is the whole split's
    ranks = [RoadEvaluator(), RoadEvaluator()]
    for i, image in enumerate(images):
        ranks[i % 2].process(*image)
    assert ranks[0].evaluate()["f_score"] != m["f_score"]
    summed = RoadEvaluator.from_vector(ranks[0].to_vector() + ranks[1].to_vector())
    assert summed.evaluate() == m
    # 8-bit maps are taken as they are: the same KITTI counts as the probabilities they encode
    conf = RoadEvaluator()
    for prob, road, valid in images:
        conf.process(to_confidence(prob), road, valid)
    keys = ("max_f", "ap", "pre", "rec")
    assert {k: conf.evaluate()[k] for k in keys} == {k: m[k] for k in keys}
    ev.reset()
    assert ev.images == 0 and ev.counts == Counts() and not ev.to_vector().any()
    with pytest.raises(ShapeMismatchError, match="519 values"):
        RoadEvaluator.from_vector(np.zeros(10))


def test_pr_curve_points_are_the_devkit_ones() -> None:
    rng = np.random.default_rng(3)
    images = [_random_image(rng) for _ in range(3)]
    total = KittiCounts()
    for image in images:
        total = total + kitti_counts(*image)
    recall, precision = total.pr_curve()
    assert recall.shape == precision.shape and recall.size > 100 and np.all(np.diff(recall) <= 0)
    f = 2 * precision * recall / (precision + recall + 1e-10)
    assert f.max() == pytest.approx(float(devkit_reference(images)["max_f"]), abs=1e-12)
    assert KittiCounts().pr_curve()[0].size == 0


def test_evaluate_kitti_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rng = np.random.default_rng(7)
    gt_dir, pred_dir = tmp_path / "gt", tmp_path / "pred"
    images = {}
    for name in ("um_road_000000", "um_road_000001", "uu_road_000000"):
        conf, road, valid = _random_image(rng)
        write_image(gt_dir / f"{name}.png", road_label_to_kitti(RoadLabel(road, valid)))
        write_image(pred_dir / f"{name}.png", conf)
        images[name] = (conf, road, valid)
    out = tmp_path / "res.json"
    assert main(["evaluate-kitti", "--gt", str(gt_dir), "--pred", str(pred_dir), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert list(res) == ["um_road", "uu_road", "all"] and res["um_road"]["images"] == 2
    ref = devkit_reference([images["um_road_000000"], images["um_road_000001"]])
    assert res["um_road"]["max_f"] == pytest.approx(float(ref["max_f"]), abs=1e-12)
    assert list(res["all"]) == ["max_f", "ap", "pre", "rec", "fpr", "fnr", "threshold", "images"]
    ref_all = devkit_reference(list(images.values()))
    for key in ("max_f", "ap", "pre", "rec", "fpr", "fnr"):
        assert res["all"][key] == pytest.approx(float(ref_all[key]), abs=1e-12), key
    assert res["all"]["images"] == 3
    assert "MaxF" in capsys.readouterr().out
    # user mistakes: a missing prediction, a size mismatch, a missing folder
    (pred_dir / "uu_road_000000.png").unlink()
    assert main(["evaluate-kitti", "--gt", str(gt_dir), "--pred", str(pred_dir),
                 "--out", str(tmp_path / "x.json")]) == 2
    assert "no prediction" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
    write_image(pred_dir / "uu_000000.png", np.zeros((10, 10), np.uint8))
    assert main(["evaluate-kitti", "--gt", str(gt_dir), "--pred", str(pred_dir),
                 "--out", str(tmp_path / "x.json")]) == 2
    assert "10×10" in capsys.readouterr().err
    assert main(["evaluate-kitti", "--gt", str(tmp_path / "no"), "--pred", str(pred_dir),
                 "--out", str(tmp_path / "x.json")]) == 2
    assert "ground-truth folder not found" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
