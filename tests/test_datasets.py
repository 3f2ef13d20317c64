"""Datasets on fake trees: KITTI road, SYNTHIA, CARLA/SYN-Stereo, generic; splits; disparity sources;
`freespace datasets info`; `freespace generate --dataset` for every layout; the torch wrapper."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

import freespace.data.disparity as disparity_sources
from freespace.cli import main
from freespace.data import get_dataset, list_datasets
from freespace.data.folder import CarlaStereo, SynthiaStereo
from freespace.data.info import check_dataset
from freespace.data.kitti_road import KittiRoad
from freespace.data.splits import make_splits, read_splits, split_sizes, write_splits
from freespace.data.synthetic import format_kitti_calib
from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError
from freespace.io.codecs import road_label_to_kitti, write_disparity, write_image

from helpers import synthetic_pair

SHAPE = (160, 320)


def _write_raw(path: Path, img: np.ndarray) -> None:
    """Write a (possibly 16-bit, RGB-ordered) image without conversion."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if img.ndim == 3:
        img = img[:, :, ::-1]
    assert cv2.imwrite(str(path), img)


def _kitti_calib(fx: float = 300.0, baseline: float = 0.5) -> str:
    P2 = np.array([[fx, 0, 160.0, 0], [0, fx, 80.0, 0], [0, 0, 1, 0]])
    P3 = P2.copy()
    P3[0, 3] = -fx * baseline
    road = np.hstack([np.eye(3), [[0], [-1.6], [0]]])
    return format_kitti_calib({"P0": P2, "P1": P3, "P2": P2, "P3": P3, "R0_rect": np.eye(3),
                               "Tr_velo_to_cam": np.eye(3, 4), "Tr_cam_to_road": road})


def kitti_tree(root: Path, n: int = 4, split: str = "training", right: bool = True, label: bool = True) -> list[str]:
    names = []
    for i in range(n):
        cat = ("um", "umm", "uu")[i % 3]
        name = f"{cat}_{i:06d}"
        left, right_img, lab, _ = synthetic_pair(SHAPE, roll_deg=0.3 * i, seed=i)
        base_dir = root / "data_road" / split
        write_image(base_dir / "image_2" / f"{name}.png", left)
        if label:
            write_image(base_dir / "gt_image_2" / f"{cat}_road_{i:06d}.png", road_label_to_kitti(lab))
        (base_dir / "calib").mkdir(parents=True, exist_ok=True)
        (base_dir / "calib" / f"{name}.txt").write_text(_kitti_calib())
        if right:
            write_image(root / "data_road_right" / split / "image_3" / f"{name}.png", right_img)
        names.append(name)
    return names


# --- KITTI road ----------------------------------------------------------------------------------------

def test_kitti_training_and_testing(tmp_path: Path) -> None:
    kitti_tree(tmp_path, 4)
    kitti_tree(tmp_path, 2, split="testing", label=False)
    train = get_dataset("kitti", tmp_path)
    assert train.split == "training" and len(train) == 4
    assert [f.name for f in train.frames] == ["um_000000", "um_000003", "umm_000001", "uu_000002"]  # sorted
    s = train.load(1)
    assert s.left.shape == SHAPE + (3,) and s.right is not None and s.label is not None
    assert s.calibration.fx == 300.0 and s.calibration.baseline == pytest.approx(0.5)
    assert s.calibration.road_plane.height == pytest.approx(1.6)
    test = KittiRoad(tmp_path, "testing", disparity_source="none")
    assert len(test) == 2 and test.load(0).label is None
    assert check_dataset(test) == []  # no labels expected in testing


def test_subset_and_labelled(tmp_path: Path) -> None:
    kitti_tree(tmp_path, 4)
    (tmp_path / "data_road" / "training" / "gt_image_2" / "um_road_000003.png").unlink()
    ds = KittiRoad(tmp_path, disparity_source="none")
    assert [f.name for f in ds.labelled()] == ["um_000000", "umm_000001", "uu_000002"]
    sub = ds.subset(["uu_000002", "um_000000"])
    assert [f.name for f in sub] == ["uu_000002", "um_000000"] and sub.index("um_000000") == 1
    np.testing.assert_array_equal(sub.load(1).left, ds.load(0).left)
    assert (sub.split, sub.disparity_source, len(ds)) == ("training", "none", 4)  # same options; ds untouched
    assert ds.subset([]).frames == []
    with pytest.raises(DatasetError, match="'um_000009' is not in kitti training"):
        ds.subset(["um_000009"])


def test_missing_root_is_the_same_error_everywhere(tmp_path: Path) -> None:
    from freespace.data.info import dataset_info

    for open_missing in (lambda: get_dataset("kitti", tmp_path / "none"), lambda: KittiRoad(tmp_path / "none"),
                         lambda: dataset_info("synthia", tmp_path / "none")):
        with pytest.raises(InputFileError, match="dataset root not found"):
            open_missing()


def test_kitti_without_right_images_and_user_disparity(tmp_path: Path) -> None:
    names = kitti_tree(tmp_path, 3, right=False)
    ds = KittiRoad(tmp_path)
    assert all(f.right is None for f in ds.frames)
    s = ds.load(0)
    assert s.right is None and s.disparity is None and s.disparity_source == "none"
    disp_dir = tmp_path / "learned"
    for i, name in enumerate(names):
        write_disparity(disp_dir / f"{name}.png", synthetic_pair(SHAPE, roll_deg=0.3 * i, seed=i)[3])
    ds = KittiRoad(tmp_path, disparity_dir=disp_dir)
    s = ds.load(2)
    assert s.disparity_source == "file" and np.nanmax(s.disparity) > 10
    with pytest.raises(InputFileError, match="disparity folder not found"):
        KittiRoad(tmp_path, disparity_dir=tmp_path / "nope")


def test_kitti_problems_are_listed_by_frame(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    kitti_tree(tmp_path, 5)
    tr = tmp_path / "data_road" / "training"
    (tmp_path / "data_road_right/training/image_3/umm_000001.png").unlink()          # missing partner
    write_image(tmp_path / "data_road_right/training/image_3/um_000099.png",          # mispaired
                np.zeros(SHAPE + (3,), np.uint8))
    (tr / "gt_image_2/uu_road_000002.png").write_bytes(b"\x89PNG\r\n\x1a\ntruncated")  # corrupt
    write_image(tr / "gt_image_2/um_road_000003.png", np.full((100, 320, 3), (255, 0, 255), np.uint8))  # wrong size
    problems = [str(p) for p in check_dataset(KittiRoad(tmp_path))]
    joined = "\n".join(problems)
    assert "umm_000001: missing right file" in joined
    assert "um_000099: right image" in joined and "has no left image" in joined
    assert "uu_000002: cannot decode" in joined
    assert "um_000003: label is 320×100 but left is 320×160" in joined
    assert len(problems) == 4
    assert main(["datasets", "info", "--dataset", "kitti", "--root", str(tmp_path), "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert "4 problems" in out and "umm_000001" in out and "training: 5 frames (um 2, umm 2, uu 1)" in out


def test_datasets_info_clean_tree_and_missing_root(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    kitti_tree(tmp_path, 3)
    assert main(["datasets", "info", "--dataset", "kitti", "--root", str(tmp_path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "320×160 (3)" in out and "right 3/3" in out and "0 problems" in out
    assert main(["datasets", "info", "--dataset", "kitti", "--root", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dataset root not found" in err


# --- SYNTHIA -------------------------------------------------------------------------------------------

def synthia_tree(root: Path, seqs=("SYNTHIA-SEQS-01-SPRING", "SYNTHIA-SEQS-02-NIGHT"), n: int = 3) -> None:
    fxb = 532.740352 * 0.8
    for k, seq in enumerate(seqs):
        for i in range(n):
            left, right, lab, disp = synthetic_pair(SHAPE, roll_deg=0.5, seed=10 * k + i)
            stem = f"{i:06d}"
            write_image(root / seq / "RGB/Stereo_Left/Omni_F" / f"{stem}.png", left)
            write_image(root / seq / "RGB/Stereo_Right/Omni_F" / f"{stem}.png", right)
            ids = np.where(lab.road, 3, 2).astype(np.uint16)
            ids[:40] = 0  # void = don't care
            _write_raw(root / seq / "GT/LABELS/Stereo_Left/Omni_F" / f"{stem}.png",
                       np.stack([ids, np.zeros_like(ids), np.zeros_like(ids)], -1))
            with np.errstate(divide="ignore"):
                cm = np.where(disp > 0.7, np.round(fxb / disp * 100), 0).clip(0, 65535).astype(np.uint16)
            _write_raw(root / seq / "Depth/Stereo_Left/Omni_F" / f"{stem}.png", np.stack([cm, cm, cm], -1))


def test_synthia(tmp_path: Path) -> None:
    synthia_tree(tmp_path)
    ds = get_dataset("synthia", tmp_path)
    assert len(ds) == 6 and ds.frames[0].name == "SYNTHIA-SEQS-01-SPRING_000000"
    assert {f.category for f in ds.frames} == {"SPRING", "NIGHT"} and len({f.scenario for f in ds.frames}) == 2
    s = ds.load(4)
    assert s.disparity_source == "depth"
    truth = synthetic_pair(SHAPE, roll_deg=0.5, seed=11)[3]
    ok = np.isfinite(s.disparity)
    assert ok.mean() > 0.7
    np.testing.assert_allclose(s.disparity[ok], truth[ok], rtol=0.01, atol=0.01)
    assert s.label.road[100, 160] and not s.label.valid[10, 10]
    assert check_dataset(ds) == []
    # a single sequence folder works as the root too; freespace.yaml overrides the defaults
    one = SynthiaStereo(tmp_path / "SYNTHIA-SEQS-01-SPRING")
    assert len(one) == 3
    (tmp_path / "freespace.yaml").write_text("road_ids: [2]\nignore_ids: []\n")
    s2 = get_dataset("synthia", tmp_path).load(0)
    assert not s2.label.road[100, 160] and s2.label.valid.all()


# --- CARLA / SYN-Stereo --------------------------------------------------------------------------------

def carla_tree(root: Path, n: int = 3, camera: bool = True) -> None:
    for seq in ("Town01_clear", "Town02_rain"):
        fx, baseline = 300.0, 1.5
        if camera:
            (root / seq).mkdir(parents=True, exist_ok=True)
            (root / seq / "camera.yaml").write_text(f"fx: {fx}\nfy: {fx}\ncx: 160\ncy: 80\nbaseline: {baseline}\n")
        for i in range(n):
            left, right, lab, disp = synthetic_pair(SHAPE, roll_deg=-0.4, seed=i)
            write_image(root / seq / "left" / f"{i:05d}.png", left)
            write_image(root / seq / "right" / f"{i:05d}.png", right)
            sem = np.where(lab.road, 7, 1).astype(np.uint8)
            write_image(root / seq / "semantic" / f"{i:05d}.png",
                        np.stack([sem, np.zeros_like(sem), np.zeros_like(sem)], -1))
            with np.errstate(divide="ignore"):
                depth = np.where(disp > 0.5, fx * baseline / disp, 1000.0)
            code = np.round(np.clip(depth, 0, 1000) / 1000.0 * (256 ** 3 - 1)).astype(np.int64)
            rgb = np.stack([code % 256, (code // 256) % 256, code // 65536], -1).astype(np.uint8)
            write_image(root / seq / "depth" / f"{i:05d}.png", rgb)


def test_carla(tmp_path: Path) -> None:
    carla_tree(tmp_path)
    ds = get_dataset("syn-stereo", tmp_path)
    assert isinstance(ds, CarlaStereo) and len(ds) == 6
    s = ds.load(1)
    truth = synthetic_pair(SHAPE, roll_deg=-0.4, seed=1)[3]
    ok = truth > 0.5
    assert s.disparity_source == "depth"
    np.testing.assert_allclose(s.disparity[ok], truth[ok], rtol=1e-3, atol=1e-3)
    assert s.calibration.baseline == 1.5
    # a disparity folder is preferred to depth
    write_disparity(tmp_path / "Town01_clear/disparity/00001.npy", truth)
    assert get_dataset("carla", tmp_path).load(1).disparity_source == "file"


def test_carla_mispaired_and_corrupt(tmp_path: Path) -> None:
    carla_tree(tmp_path, camera=False)
    (tmp_path / "Town02_rain/right/00002.png").rename(tmp_path / "Town02_rain/right/00007.png")
    (tmp_path / "Town01_clear/depth/00000.png").write_bytes(b"junk")
    problems = [str(p) for p in check_dataset(CarlaStereo(tmp_path))]
    assert any(p.startswith("Town02_rain_00007: right file") for p in problems)
    assert "Town02_rain_00002: missing right file" in problems
    assert any(p.startswith("Town01_clear_00000: cannot decode") for p in problems)
    assert CarlaStereo(tmp_path).calibration(CarlaStereo(tmp_path).frames[0]).fx == 320.0  # default camera


# --- generic -------------------------------------------------------------------------------------------

def generic_tree(root: Path, n: int = 4) -> None:
    (root / "freespace.yaml").parent.mkdir(parents=True, exist_ok=True)
    (root / "freespace.yaml").write_text(
        "left: L\nright: R\nlabel: M\ndisparity: D\nlabel_encoding: mask\n"
        "scenario_pattern: '^(?P<scenario>drive\\d+)_'\n")
    for i in range(n):
        left, right, lab, disp = synthetic_pair(SHAPE, roll_deg=1.0, seed=i)
        name = f"drive{i // 2}_{i:03d}"
        write_image(root / "L" / f"{name}.png", left)
        write_image(root / "R" / f"{name}.png", right)
        write_image(root / "M" / f"{name}.png", lab.road.astype(np.uint8) * 255)
        write_disparity(root / "D" / f"{name}.npy", disp)


def test_generic(tmp_path: Path) -> None:
    generic_tree(tmp_path)
    ds = get_dataset("generic", tmp_path)
    assert [f.scenario for f in ds.frames] == ["drive0", "drive0", "drive1", "drive1"]
    s = ds.load(0)
    assert s.disparity_source == "file" and s.label.road.any() and s.calibration is None
    assert check_dataset(ds) == []


def test_generic_config_mistakes(tmp_path: Path) -> None:
    (tmp_path / "L").mkdir()
    with pytest.raises(InputFileError, match="freespace.yaml not found"):
        get_dataset("generic", tmp_path)
    (tmp_path / "freespace.yaml").write_text("left: L\ncolour: red\n")
    with pytest.raises(InvalidOptionError, match="unknown keys"):
        get_dataset("generic", tmp_path)
    (tmp_path / "freespace.yaml").write_text("left: [unclosed\n")
    with pytest.raises(CorruptFileError, match="cannot parse .*freespace.yaml"):
        get_dataset("generic", tmp_path)
    (tmp_path / "freespace.yaml").write_text("left: L\n")
    with pytest.raises(DatasetError, match="no frames"):
        get_dataset("generic", tmp_path)
    with pytest.raises(InvalidOptionError, match="choose one of"):
        get_dataset("cityscapes", tmp_path)
    assert {"kitti", "synthia", "carla", "syn-stereo", "generic", "synth"} <= set(list_datasets())


# --- disparity sources -----------------------------------------------------------------------------------

def test_sgbm_disparity_is_cached(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    kitti_tree(tmp_path / "k", 2)
    ds = KittiRoad(tmp_path / "k", cache_dir=tmp_path / "cache")
    first = ds.load(0)
    assert first.disparity_source == "sgbm" and len(list((tmp_path / "cache").glob("*.npy"))) == 1

    def boom(*args, **kwargs):
        raise AssertionError("SGBM ran again")

    monkeypatch.setattr(disparity_sources, "compute_disparity", boom)
    again = KittiRoad(tmp_path / "k", cache_dir=tmp_path / "cache").load(0)
    np.testing.assert_array_equal(again.disparity, first.disparity)
    other = KittiRoad(tmp_path / "k", cache_dir=tmp_path / "cache", max_disparity=64)
    with pytest.raises(AssertionError, match="SGBM ran again"):  # new settings, new key
        other.load(0)
    assert KittiRoad(tmp_path / "k", disparity_source="none").load(0).disparity is None


# --- splits --------------------------------------------------------------------------------------------

def test_split_sizes() -> None:
    assert split_sizes(289) == (173, 58, 58) and split_sizes(300) == (180, 60, 60)
    assert split_sizes(50) == (30, 10, 10) and sum(split_sizes(7)) == 7


def test_splits_by_scenario_deterministic(tmp_path: Path) -> None:
    kitti = [(f"um_{i:06d}", f"um_{i:06d}") for i in range(289)]
    s = make_splits(kitti, seed=0)
    assert [len(s[k]) for k in ("train", "val", "test")] == [173, 58, 58]
    assert make_splits(kitti, seed=0) == s and make_splits(kitti, seed=1) != s
    synth = [(f"f{i:03d}", f"sc{i // 10}") for i in range(300)]
    t = make_splits(synth, seed=3)
    assert [len(t[k]) for k in ("train", "val", "test")] == [180, 60, 60]
    scen = {name: sc for name, sc in synth}
    for a in ("train", "val", "test"):
        for b in ("train", "val", "test"):
            if a < b:
                assert not {scen[n] for n in t[a]} & {scen[n] for n in t[b]}
    write_splits(tmp_path, t)
    assert read_splits(tmp_path, known=[n for n, _ in synth]) == t
    assert (tmp_path / "test.txt").read_text().splitlines() == t["test"]
    with pytest.raises(DatasetError, match="not in the dataset"):
        read_splits(tmp_path, known=["f000"])
    (tmp_path / "val.txt").write_text((tmp_path / "train.txt").read_text())
    with pytest.raises(DatasetError, match="more than one split"):
        read_splits(tmp_path)
    with pytest.raises(InputFileError):
        read_splits(tmp_path / "none")


# --- generate on every layout ----------------------------------------------------------------------------

@pytest.mark.parametrize("layout", ["kitti", "synthia", "carla", "generic"])
def test_generate_on_every_layout(layout: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "data"
    {"kitti": lambda r: kitti_tree(r, 2), "synthia": lambda r: synthia_tree(r, n=1),
     "carla": lambda r: carla_tree(r, n=1), "generic": lambda r: generic_tree(r, 2)}[layout](root)
    out = tmp_path / "gen"
    assert main(["generate", "--dataset", layout, "--root", str(root), "--out", str(out),
                 "--cache-dir", str(tmp_path / "cache")]) == 0
    assert "2 generated" in capsys.readouterr().out
    assert len(list(out.glob("*.png"))) == 2


# --- torch wrapper -------------------------------------------------------------------------------------

def test_torch_dataset(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from freespace.data.torch_dataset import RoadSegmentationDataset
    from freespace.labels import IGNORE_INDEX

    kitti_tree(tmp_path, 3)
    ds = RoadSegmentationDataset(KittiRoad(tmp_path, disparity_source="none"))
    item = ds[0]
    assert item["image"].shape == (3,) + SHAPE and item["image"].dtype == torch.float32
    assert 0 <= float(item["image"].min()) and float(item["image"].max()) <= 1
    labels = set(torch.unique(item["label"]).tolist())
    assert labels == {0, 1, IGNORE_INDEX}
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=2)))
    assert batch["image"].shape == (2, 3) + SHAPE and batch["name"] == ["um_000000", "umm_000001"]
    kitti_tree(tmp_path / "t", 1, split="testing", label=False)
    with pytest.raises(DatasetError, match="no road label"):
        RoadSegmentationDataset(KittiRoad(tmp_path / "t", "testing"), names=["um_000000"])


def test_torch_dataset_training_options(tmp_path: Path) -> None:
    """Resize (labels nearest), image overrides (DS-Generator views), cache, augmentation drawn from
    (seed, epoch, i) only."""
    torch = pytest.importorskip("torch")
    from freespace.data.torch_dataset import Item, RoadSegmentationDataset
    from freespace.labels import IGNORE_INDEX

    names = kitti_tree(tmp_path, 3)
    kitti = KittiRoad(tmp_path, disparity_source="none")
    view = np.full(SHAPE + (3,), 200, np.uint8)
    write_image(tmp_path / "view.png", view)
    items = [Item(kitti.index(names[0]), names[0]), Item(kitti.index(names[1]), names[1], str(tmp_path / "view.png"))]
    plain = RoadSegmentationDataset(kitti, items, size=(40, 80))
    cached = RoadSegmentationDataset(kitti, items, size=(40, 80), cache=True)
    a, b = plain[1], cached[1]
    assert a["image"].shape == (3, 40, 80) and a["name"] == names[1] and a["index"] == 1
    assert torch.equal(a["image"], torch.full((3, 40, 80), 200 / 255.0))  # the override image, resized
    full = RoadSegmentationDataset(kitti, items)[1]["label"]
    assert torch.equal(a["label"], full[::4, ::4])  # nearest (OpenCV: source pixel 4·i): no new values
    assert torch.equal(a["label"], b["label"]) and set(cached._cache) == {(1, str(tmp_path / "view.png"))} \
        and not plain._cache
    aug = RoadSegmentationDataset(kitti, items, size=(40, 80), affine=True, seed=3)
    again = RoadSegmentationDataset(kitti, items, size=(40, 80), affine=True, seed=3)
    draws = [aug[(e, 0)]["label"] for e in range(4)]
    assert all(torch.equal(d, again[(e, 0)]["label"]) for e, d in enumerate(draws))  # (seed, epoch, i) only
    assert not all(torch.equal(draws[0], d) for d in draws[1:])  # epochs differ
    assert set(torch.unique(torch.stack(draws)).tolist()) <= {0, 1, IGNORE_INDEX}


def test_torch_dataset_flip_and_photometric(tmp_path: Path) -> None:
    """``flip`` mirrors image and label together, about half the draws; ``photometric`` changes the colours and
    never the label; both are drawn from (seed, epoch, i) only; ``affine`` alone keeps the paper's draws."""
    torch = pytest.importorskip("torch")
    from freespace.data.torch_dataset import RoadSegmentationDataset

    names = kitti_tree(tmp_path, 1)
    kitti = KittiRoad(tmp_path, disparity_source="none")
    plain = RoadSegmentationDataset(kitti, names)[0]
    flips = RoadSegmentationDataset(kitti, names, flip=True, seed=1)
    mirrored = []
    for e in range(40):
        s = flips[(e, 0)]
        if torch.equal(s["image"], plain["image"]):
            assert torch.equal(s["label"], plain["label"])
            mirrored.append(False)
        else:  # mirrored: the image and its label with it
            assert torch.equal(s["image"], plain["image"].flip(-1)) and torch.equal(s["label"], plain["label"].flip(-1))
            mirrored.append(True)
    assert 10 <= sum(mirrored) <= 30
    assert [torch.equal(flips[(e, 0)]["image"], plain["image"]) for e in range(40)] == [not m for m in mirrored]

    colour = RoadSegmentationDataset(kitti, names, photometric=True, seed=1)
    draws = [colour[(e, 0)] for e in range(10)]
    assert all(torch.equal(d["label"], plain["label"]) for d in draws)
    assert sum(not torch.equal(d["image"], plain["image"]) for d in draws) >= 5
    assert all(torch.equal(d["image"], colour[(e, 0)]["image"]) for e, d in enumerate(draws))

    # the paper's augmentation alone draws as it did before these options: its own pipeline of one step
    import albumentations as A

    from freespace.data.torch_dataset import _augmenter

    assert [type(t) for t in _augmenter(True, False, False).transforms] == [A.Affine]
    assert [type(t) for t in _augmenter(True, True, True).transforms] == [A.ColorJitter, A.HorizontalFlip, A.Affine]
    assert _augmenter(False, False, False) is None


def test_torch_dataset_zoom_scales_image_and_label_together(tmp_path: Path) -> None:
    """``zoom`` adds a scale in 1 ± zoom to the conventional augmentation: image and label move together (the
    label keeps its classes, zoomed-out borders are don't care), the road's share spreads wider over the draws
    than with translation and rotation alone, the draws repeat for (seed, epoch, i); zoom 0 keeps the paper's
    draws, and a zoom outside [0, 0.5] is refused."""
    torch = pytest.importorskip("torch")
    from freespace.data.torch_dataset import RoadSegmentationDataset
    from freespace.labels import IGNORE_INDEX

    names = kitti_tree(tmp_path, 1)
    kitti = KittiRoad(tmp_path, disparity_source="none")
    spread, ignored = {}, {}
    for zoom in (0.0, 0.4):
        ds = RoadSegmentationDataset(kitti, names, affine=True, zoom=zoom, seed=5)
        draws = [ds[(e, 0)] for e in range(40)]
        labels = torch.stack([d["label"] for d in draws])
        assert set(torch.unique(labels).tolist()) <= {0, 1, IGNORE_INDEX}
        assert all(torch.equal(d["image"], ds[(e, 0)]["image"]) for e, d in enumerate(draws))
        road = (labels == 1).float().mean((1, 2))
        spread[zoom], ignored[zoom] = float(road.max() - road.min()), float((labels == IGNORE_INDEX).float().mean())
    plain = RoadSegmentationDataset(kitti, names, affine=True, seed=5)
    zero = RoadSegmentationDataset(kitti, names, affine=True, seed=5, zoom=0.0)
    assert all(torch.equal(plain[(e, 0)]["label"], zero[(e, 0)]["label"]) for e in range(5))
    assert spread[0.4] > 1.2 * spread[0.0] and ignored[0.4] > ignored[0.0]
    with pytest.raises(ValueError, match="zoom must be in"):
        RoadSegmentationDataset(kitti, names, zoom=0.8)


def test_torch_dataset_crop_top_cuts_image_and_label_together(tmp_path: Path) -> None:
    """``crop_top`` cuts the top t × H rows (t in [0, crop_top]) and stretches the rest back: image and label stay
    aligned (the road's top edge moves up the frame by the same rows in both), the label keeps its classes, the
    draws repeat for (seed, epoch, i) and leave the other augmentations' draws as they were; out of [0, 0.7) is
    refused."""
    torch = pytest.importorskip("torch")
    import numpy as np

    from freespace.data.torch_dataset import RoadSegmentationDataset, cut_top

    image = np.zeros((10, 4, 3), np.uint8)
    image[6:] = 200  # "road" from row 6 down, in the image and the label alike
    label = (np.arange(10)[:, None] >= 6).repeat(4, 1).astype(np.uint8)
    cut_image, cut_label = cut_top(image, label, 0.5)  # rows 5–9 stretched to 10: road from row 2 down
    assert cut_label[:, 0].tolist() == [0, 0, 1, 1, 1, 1, 1, 1, 1, 1]
    assert (cut_image[3:, :, 0] == 200).all() and (cut_image[0, :, 0] == 0).all()  # row 1 blends the two
    assert cut_top(image, label, 0.01)[1] is label  # less than a row: unchanged

    names = kitti_tree(tmp_path, 1)
    kitti = KittiRoad(tmp_path, disparity_source="none")
    plain = RoadSegmentationDataset(kitti, names, flip=True, seed=5)
    cut = RoadSegmentationDataset(kitti, names, flip=True, seed=5, crop_top=0.5)
    first_road = []
    for e in range(20):
        a, b = plain[(e, 0)], cut[(e, 0)]
        assert set(torch.unique(b["label"]).tolist()) <= set(torch.unique(a["label"]).tolist())
        assert torch.equal(b["image"], cut[(e, 0)]["image"]) and torch.equal(b["label"], cut[(e, 0)]["label"])
        rows = [int((d["label"] == 1).any(1).nonzero()[0]) for d in (a, b)]
        assert rows[1] <= rows[0]
        first_road.append(rows[0] - rows[1])
        # the mirror drawn for (seed, epoch, i) is the same with and without the cut: the label's columns agree
        assert torch.equal(b["label"][-1], a["label"][-1])
    assert len(set(first_road)) > 5  # the cut varies over the epochs
    for bad in (-0.1, 0.7):
        with pytest.raises(ValueError, match="crop_top must be in"):
            RoadSegmentationDataset(kitti, names, crop_top=bad)


def test_torch_dataset_strong_photometric(tmp_path: Path) -> None:
    """``photometric="strong"`` darkens, blurs and adds noise besides the jitter: its draws spread the image's mean
    brightness wider than the mild ones, never touch the label, and repeat for (seed, epoch, i); a strength that
    is not one of PHOTOMETRIC is refused."""
    torch = pytest.importorskip("torch")
    import albumentations as A

    from freespace.data.torch_dataset import PHOTOMETRIC, RoadSegmentationDataset, _augmenter, photometric_strength

    names = kitti_tree(tmp_path, 1)
    kitti = KittiRoad(tmp_path, disparity_source="none")
    plain = RoadSegmentationDataset(kitti, names)[0]
    spread = {}
    for strength in ("mild", "strong"):
        ds = RoadSegmentationDataset(kitti, names, photometric=strength, seed=2)
        draws = [ds[(e, 0)] for e in range(30)]
        assert all(torch.equal(d["label"], plain["label"]) for d in draws)
        assert all(torch.equal(d["image"], ds[(e, 0)]["image"]) for e, d in enumerate(draws))
        means = torch.stack([d["image"].mean() for d in draws])
        spread[strength] = float(means.max() - means.min())
    assert spread["strong"] > 1.5 * spread["mild"]
    assert _augmenter(False, False, "strong") is None  # drawn apart, from its own generator
    assert [type(t) for t in _augmenter(False, True, "strong").transforms] == [A.HorizontalFlip]
    assert [photometric_strength(v) for v in (False, True, *PHOTOMETRIC)] == ["off", "mild", *PHOTOMETRIC]
    with pytest.raises(ValueError, match="photometric must be one of"):
        photometric_strength("loud")


def test_datasets_split_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    synthia_tree(tmp_path / "two", n=5)  # two scenarios cannot fill three splits: refused, nothing written
    assert main(["datasets", "split", "--dataset", "synthia", "--root", str(tmp_path / "two"), "--out",
                 str(tmp_path / "none")]) == 2
    assert "leaves val empty" in capsys.readouterr().err and not (tmp_path / "none").exists()
    synthia_tree(tmp_path / "s", seqs=tuple(f"SYNTHIA-SEQS-0{i}-SPRING" for i in range(1, 6)))  # 5 × 3 frames: 9/3/3
    out = tmp_path / "lists"
    assert main(["datasets", "split", "--dataset", "synthia", "--root", str(tmp_path / "s"), "--out", str(out)]) == 0
    lists = read_splits(out)
    names = [f.name for f in get_dataset("synthia", tmp_path / "s").frames]
    assert sorted(n for v in lists.values() for n in v) == names
    scenarios = [{n.rsplit("_", 1)[0] for n in lists[k]} for k in ("train", "val", "test")]
    assert not (scenarios[0] & scenarios[1] or scenarios[0] & scenarios[2] or scenarios[1] & scenarios[2])
    assert "train" in capsys.readouterr().out
