"""Your labels, your camera (issue 69): train on a labelled folder in the formats people have (binary masks, class
ids, colour palettes, public sets' presets), fine-tune from a checkpoint or a model folder, end in a model folder;
and every bad input refused in one line with nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from freespace.cli import main
from freespace.data.labelled_folder import held_out_by_name
from freespace.evaluation.label_presets import LABEL_PRESETS, preset_format, resolve_label_format
from freespace.evaluation.labelled import parse_label_format
from freespace.io.codecs import write_image

from helpers import refused

SIZE = (64, 96)  # H, W
CAMVID_ROAD, CAMVID_VOID, CAMVID_SKY = 3, 11, 0


def _frame(i: int, size: tuple[int, int] = SIZE) -> tuple[np.ndarray, np.ndarray]:
    """A frame whose lower part is grey road (with noise) under a blue sky, and its road mask (bool)."""
    h, w = size
    rng = np.random.default_rng(i)
    img = np.empty((h, w, 3), np.uint8)
    img[:] = (70, 120, 200)
    top = h // 2 + i % 5
    img[top:] = 110
    img += rng.integers(0, 20, img.shape, dtype=np.uint8)
    road = np.zeros((h, w), bool)
    road[top:] = True
    return img, road


def make_folder(root: Path, n: int, kind: str = "class-id", *, size: tuple[int, int] = SIZE) -> tuple[Path, Path]:
    """``n`` frames ``f00.png`` … in ``root/images`` with labels in ``root/labels`` written as ``kind``: class-id
    (CamVid ids: road 3, sky 0, a void band 11), binary (0/255), palette (Cityscapes colours)."""
    images, labels = root / "images", root / "labels"
    images.mkdir(parents=True, exist_ok=True)
    labels.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        img, road = _frame(i, size)
        write_image(images / f"f{i:02d}.png", img)
        if kind == "binary":
            label = np.where(road, 255, 0).astype(np.uint8)
        elif kind == "palette":
            label = np.zeros(road.shape + (3,), np.uint8)
            label[:] = (70, 130, 180)
            label[road] = (128, 64, 128)
        else:
            label = np.where(road, CAMVID_ROAD, CAMVID_SKY).astype(np.uint8)
            label[:2] = CAMVID_VOID
        write_image(labels / f"f{i:02d}.png", label)
    return images, labels


def _train(images: Path, labels: Path, out: Path, *extra: str) -> int:
    return main(["train", "--images", str(images), "--labels", str(labels), "--out", str(out), "--model", "segnet",
                 "--batch-size", "2", "--epochs", "1", "--no-progress", *extra])


@pytest.fixture(scope="module")
def folder_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A SegNet trained one epoch on 10 CamVid-style frames (``--labels-like camvid``)."""
    root = tmp_path_factory.mktemp("own")
    images, labels = make_folder(root, 10)
    run = root / "run"
    assert _train(images, labels, run, "--labels-like", "camvid") == 0
    return {"root": root, "images": images, "labels": labels, "run": run}


def test_a_labelled_folder_trains_and_holds_out_the_last_frames_by_name(folder_run: dict[str, Path]) -> None:
    run = folder_run["run"]
    splits = {k: (run / "splits" / f"{k}.txt").read_text().split() for k in ("train", "val", "test")}
    assert splits["train"] == [f"f{i:02d}" for i in range(8)] and splits["val"] == ["f08", "f09"]
    assert splits["test"] == splits["val"]
    m = json.loads((run / "metrics.json").read_text())
    record = m["labelled_folder"]
    assert record["labels_like"] == "camvid" and record["label_format"]["road"] == [3]
    assert record["frames"] == {"train": 8, "val": 2} and "the last 2 of the 10 frames" in record["validation"]
    inputs = json.loads((run / "inputs.json").read_text())
    assert inputs["images"]["files"] == 10 and inputs["labels"]["files"] == 10 and len(inputs["labels"]["sha256"]) == 64
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["dataset"] is None and config["images"] == str(folder_run["images"].resolve())


@pytest.mark.parametrize("kind, fmt", [("binary", ["--label-format", "binary"]),
                                       ("class-id", ["--label-format", "class-id", "--road", "3", "--ignore", "11"]),
                                       ("palette", ["--labels-like", "cityscapes-color"]),
                                       ("palette", ["--label-format", "palette", "--road", "128,64,128"])])
def test_every_label_format_trains(tmp_path: Path, kind: str, fmt: list[str]) -> None:
    images, labels = make_folder(tmp_path, 6, kind)
    val_images, val_labels = make_folder(tmp_path / "v", 2, kind)
    for p in (val_images, val_labels):  # other names than the training frames
        for f in sorted(p.iterdir()):
            f.rename(f.with_name("v" + f.name))
    out = tmp_path / "run"
    assert _train(images, labels, out, *fmt, "--val-images", str(val_images), "--val-labels", str(val_labels)) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["labelled_folder"]["frames"] == {"train": 6, "val": 2} and 0 <= m["f_score"] <= 1


def test_the_library_entry_takes_a_labelled_folder(tmp_path: Path) -> None:
    import freespace

    images, labels = make_folder(tmp_path, 6, "binary")
    m = freespace.train(out=tmp_path / "run", images=images, labels=labels, label_format="binary", model="segnet",
                        batch_size=2, epochs=1, val_share=0.0, progress=False)
    assert m["labelled_folder"]["validation"].startswith("none held out")
    assert m["frames"] == {"train": 6, "val": 6, "test": 6}


def test_fine_tuning_starts_from_the_init_and_takes_its_network(folder_run: dict[str, Path], tmp_path: Path) -> None:
    init = folder_run["run"] / "checkpoints" / "best.ckpt"
    out = tmp_path / "ft"
    # a learning rate too small to move a weight: the fine-tuned checkpoint is the init's, norms frozen included
    assert _train(folder_run["images"], folder_run["labels"], out, "--labels-like", "camvid", "--init", str(init),
                  "--lr", "1e-12") == 0
    before = torch.load(init, weights_only=True)["state_dict"]
    after = torch.load(out / "checkpoints" / "best.ckpt", weights_only=True)["state_dict"]
    nets = [k for k in before if k.startswith("net.")]
    assert nets and all(torch.allclose(before[k].float(), after[k].float(), atol=1e-6) for k in nets)
    m = json.loads((out / "metrics.json").read_text())
    assert m["init"]["freeze"] == "norm" and m["init"]["path"] == str(init.resolve())
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["model"] == "segnet" and config["image_size"] == list(SIZE)
    assert json.loads((out / "inputs.json").read_text())["init"]["sha256"]


def test_fine_tuning_refuses_what_contradicts_the_init(folder_run: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    init = str(folder_run["run"] / "checkpoints" / "best.ckpt")
    base = ["train", "--images", str(folder_run["images"]), "--labels", str(folder_run["labels"]), "--labels-like",
            "camvid", "--out", str(tmp_path / "x"), "--init", init]
    refused(capsys, [*base, "--model", "deeplabv3plus"], match="contradicts it")
    refused(capsys, [*base, "--image-size", "32x48"], match="was trained at 64x96")
    refused(capsys, [*base, "--model", "segnet", "--encoder-weights", "imagenet"], match="gives every weight")
    refused(capsys, [*base[:-1], str(tmp_path)], match="a folder without model.ckpt")
    refused(capsys, [*base[:-1], str(tmp_path / "nope")], match="init not found")
    assert not (tmp_path / "x").exists()


def test_a_model_folder_from_a_run_is_a_start_and_a_predictor(folder_run: dict[str, Path], tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    run, folder = folder_run["run"], tmp_path / "my-model"
    ev = tmp_path / "eval"
    assert main(["evaluate", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--images",
                 str(folder_run["images"]), "--labels", str(folder_run["labels"]), "--labels-like", "camvid",
                 "--out", str(ev), "--no-progress", "--no-overlays"]) == 0
    refused(capsys, ["export", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--format", "folder", "--out",
                     str(folder)], match="needs --licence")
    assert not folder.exists()
    assert main(["export", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--format", "folder", "--out",
                 str(folder), "--licence", "CC BY 4.0 <b>|test|</b>", "--measured", str(ev)]) == 0
    assert {p.name for p in folder.iterdir()} >= {"model.onnx", "model.ckpt", "README.md", "metrics.json"}
    card = (folder / "README.md").read_text()
    assert "CC BY 4.0 &lt;b&gt;\\|test\\|&lt;/b&gt;" in card and "camvid labels" in card and "| `eval` " in card
    assert '{"preset": ' in card and "&quot;" not in card  # the network's options read as written
    ckpt = torch.load(folder / "model.ckpt", weights_only=True)
    assert ckpt["hyper_parameters"]["image_size"] == list(SIZE)
    assert all(v.dtype != torch.float16 for v in ckpt["state_dict"].values())  # as trained
    refused(capsys, ["export", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--format", "onnx", "--out",
                     str(tmp_path / "m.onnx"), "--kernels", "float16"], match="--kernels is for --format folder")
    assert not (tmp_path / "m.onnx").exists()
    half = tmp_path / "half"
    assert main(["export", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--format", "folder", "--out",
                 str(half), "--licence", "CC BY 4.0", "--kernels", "float16"]) == 0
    small = torch.load(half / "model.ckpt", weights_only=True)["state_dict"]
    kernels = {k for k, v in small.items() if v.dtype == torch.float16}
    assert kernels and all(small[k].dim() == 4 or k.endswith("classifier.weight") for k in kernels)
    assert all(v.dtype == ckpt["state_dict"][k].dtype for k, v in small.items() if k not in kernels)
    assert all(torch.equal(small[k].float(), ckpt["state_dict"][k].half().float()) for k in kernels)
    assert (half / "model.ckpt").stat().st_size < 0.75 * (folder / "model.ckpt").stat().st_size
    assert "convolution kernels in float16" in (half / "README.md").read_text()
    import onnx
    from onnx import numpy_helper

    from freespace.inference.export import export_model

    export_model(half / "model.ckpt", "onnx", tmp_path / "again.onnx", fp16=True)  # the folder's ONNX, bit for bit
    for a, b in zip(*(onnx.load(str(p)).graph.initializer for p in (half / "model.onnx", tmp_path / "again.onnx"))):
        assert np.array_equal(numpy_helper.to_array(a), numpy_helper.to_array(b)), a.name
    out = tmp_path / "ft"
    assert _train(folder_run["images"], folder_run["labels"], out, "--labels-like", "camvid", "--init",
                  str(half)) == 0
    assert main(["predict", "--onnx", str(folder / "model.onnx"), "--input", str(folder_run["images"]), "--out",
                 str(tmp_path / "masks"), "--no-overlays"]) == 0


# --- bad inputs: one line, exit 2, nothing written -------------------------------------------------------------


def _bad(capsys: pytest.CaptureFixture, tmp_path: Path, images: Path, labels: Path, *extra: str, match: str) -> None:
    out = tmp_path / "out"
    refused(capsys, ["train", "--images", str(images), "--labels", str(labels), "--out", str(out), "--model",
                     "segnet", "--batch-size", "2", "--epochs", "1", *extra], match=match)
    assert not out.exists(), "nothing is written"


def test_images_and_labels_that_do_not_pair(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path, 6)
    for i in (4, 5):
        (labels / f"f{i:02d}.png").unlink()
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid",
         match="2 of the 6 images in")
    err = refused(capsys, ["train", "--images", str(images), "--labels", str(labels), "--labels-like", "camvid",
                           "--out", str(tmp_path / "o")])
    assert "f04.png, f05.png" in err
    images2, labels2 = make_folder(tmp_path / "b", 6)
    for i in (1, 2, 3):
        (images2 / f"f{i:02d}.png").unlink()
    _bad(capsys, tmp_path, images2, labels2, "--labels-like", "camvid", match="3 labels in")


def test_labels_of_another_size_or_kind(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path, 6)
    write_image(labels / "f03.png", np.full((32, 48), CAMVID_ROAD, np.uint8))
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", match="1 label is not the size of its image")
    images, labels = make_folder(tmp_path / "rgb", 6, "palette")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", match="is a colour image")
    _bad(capsys, tmp_path, images, labels, "--label-format", "class-id", "--road", "3", match="is a colour image")
    images, labels = make_folder(tmp_path / "grey", 6, "class-id")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "mapillary", match="is a grey image")


def test_road_that_no_label_holds(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path, 6)
    _bad(capsys, tmp_path, images, labels, "--label-format", "class-id", "--road", "7", match="road 7 is in no label")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "cityscapes", match="road 7 is in no label")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "bdd100k-drivable", match="they are not bdd100k")
    empty_images, empty_labels = make_folder(tmp_path / "e", 6, "binary")
    for p in empty_labels.iterdir():
        write_image(p, np.zeros(SIZE, np.uint8))
    _bad(capsys, tmp_path, empty_images, empty_labels, "--label-format", "binary", match="marks road")


def test_options_that_do_not_go_together(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path, 6)
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--batch-size", "8",
         match="4 training frames are fewer than --batch-size 8")  # two of six held out
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--road", "3", match="leave out --road")
    _bad(capsys, tmp_path, images, labels, match="needs its labels' format")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--augment", "homography",
         match="needs right images")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--dataset", "kitti", match="give one or the "
                                                                                                    "other")
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--val-images", str(images),
         match="--val-images and --val-labels together")
    _bad(capsys, tmp_path, images, labels, "--label-format", "class-id", "--road", "3", "--ignore", "3",
         match="both --road and --ignore")
    refused(capsys, ["train", "--dataset", "kitti", "--root", str(tmp_path), "--out", str(tmp_path / "o"),
                     "--road", "3"], match="is for a labelled folder")


def test_the_same_frame_to_train_and_validate_on(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path, 6)
    _bad(capsys, tmp_path, images, labels, "--labels-like", "camvid", "--val-images", str(images), "--val-labels",
         str(labels), match="in both the training and the validation images")


# --- presets ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(LABEL_PRESETS))
def test_every_preset_is_a_consistent_format(name: str) -> None:
    p = LABEL_PRESETS[name]
    sep = ";" if p.kind == "palette" else ","

    def text(values: tuple) -> str | None:
        return sep.join(",".join(map(str, v)) if isinstance(v, tuple) else str(v) for v in values) or None

    # the preset as the explicit options would give it: road and don't care apart, within the tolerance too
    explicit = parse_label_format(p.kind, text(p.road), text(p.ignore), p.tolerance if p.kind == "palette" else None)
    preset = preset_format(name)
    assert (explicit.kind, explicit.road, explicit.ignore, explicit.tolerance) == \
        (preset.kind, preset.road, preset.ignore, preset.tolerance) and p.source and preset.preset == name


def test_presets_decode_as_their_sets_define_road() -> None:
    ids = np.array([[7, 8, 9, 26, 0]], np.uint8)
    label = preset_format("cityscapes").decode(ids)
    assert label.road.tolist() == [[True, False, False, False, False]]
    assert label.valid.tolist() == [[True, True, False, True, False]]  # parking and unlabeled don't care
    bdd = np.array([[0, 1, 2]], np.uint8)
    assert preset_format("bdd100k-drivable").decode(bdd).road.tolist() == [[True, True, False]]
    assert preset_format("bdd100k-drivable-2018").decode(bdd).road.tolist() == [[False, True, True]]
    vistas = np.array([[[128, 64, 128], [255, 255, 255], [244, 35, 232], [120, 10, 10]]], np.uint8)
    label = preset_format("mapillary").decode(vistas)
    assert label.road.tolist() == [[True, True, False, False]] and label.valid.tolist() == [[True, True, True, False]]
    with pytest.raises(Exception, match="leave out road"):
        resolve_label_format(None, "camvid", road="3")


def test_held_out_by_name_keeps_training_frames() -> None:
    names = [f"{i:03d}" for i in range(20)]
    assert held_out_by_name(names, 0.2) == (names[:16], names[16:])
    assert held_out_by_name(names[:1], 0.5) == (names[:1], [])  # never all
    assert held_out_by_name(names[::-1], 0.0) == (names, [])
