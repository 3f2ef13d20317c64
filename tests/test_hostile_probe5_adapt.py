"""``freespace adapt`` against the hostile probe of issue 72: one test per class of defect, each trying several
members of its class.

A tiny Fast-SCNN (:func:`helpers.tiny_road_checkpoint`, 32×96) in a model folder made here, and variants of its
checkpoint (a classifier that is sure of nothing, sees road everywhere or nowhere, overflows); the published
``models/real-road-fast`` where the frames' content matters (it finds no road on black or sky frames; the tiny
model's masks say nothing of them). Runs are one short round; refusals are checked to come before any training.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.io.codecs import write_image

from helpers import refused, road_frame, tiny_model_folder

pytest.importorskip("onnxruntime")

SIZE = (32, 96)
ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "models" / "real-road-fast"


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A model folder: ``model.ckpt`` (the tiny network) and a card."""
    return tiny_model_folder(tmp_path_factory.mktemp("models"), SIZE)


def _frames(folder: Path, n: int, seed: int = 500, image: np.ndarray | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        write_image(folder / f"f{i:03d}.png", road_frame((48, 120), seed + i)[0] if image is None else image)
    return folder


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _frames(tmp_path_factory.mktemp("frames") / "cam", 24)


def _variant(model: Path, folder: Path, change) -> Path:
    """A model folder beside the tests' with the tiny checkpoint changed by ``change(checkpoint dict)``."""
    import torch

    folder.mkdir(parents=True)
    ckpt = torch.load(model / "model.ckpt", map_location="cpu", weights_only=True)
    change(ckpt)
    torch.save(ckpt, folder / "model.ckpt")
    return folder


def _classifier(bias: tuple[float, float]):
    """A change that makes the network's output the constant logits ``bias`` (not road, road)."""
    import torch

    def change(ckpt: dict) -> None:
        ckpt["state_dict"]["net.classifier.3.weight"].zero_()
        ckpt["state_dict"]["net.classifier.3.bias"][:] = torch.tensor(bias)
    return change


def _argv(model: Path, inputs: Path | str, out: Path, *extra: str) -> list[str]:
    return ["adapt", "--model", str(model), "--input", str(inputs), "--out", str(out), "--epochs", "1",
            "--threads", "1", "--no-progress", *extra]


def _last_error(capsys: pytest.CaptureFixture) -> str:
    """The one error line (the rounds' log lines may come before it)."""
    lines = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in lines if line.startswith("freespace: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0] and not any("Traceback" in x for x in lines), lines
    return errors[0]


@pytest.fixture
def no_training(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record every training round started (a refusal before training starts none)."""
    import freespace.engine.adapt as adapt_module

    rounds: list[int] = []
    train_round = adapt_module._train_round

    def counted(*args, **kwargs):
        rounds.append(1)
        return train_round(*args, **kwargs)

    monkeypatch.setattr(adapt_module, "_train_round", counted)
    return rounds


# --- 1. a diverged or collapsed student ends the run: TrainingError, exit 1, no folder -----------------------------


@pytest.mark.parametrize("case", ["lr 0.1", "lr 1", "no confident pixel in a round"])
def test_a_diverged_student_ends_the_run_with_exit_1_and_no_folder(case: str, model: Path, frames: Path,
                                                                    tmp_path: Path, monkeypatch, capsys) -> None:
    """A loss that grows by orders of magnitude (1e7 at lr 0.1 on the tiny model) or becomes NaN, and a round in
    which the teacher is sure of no pixel (the labels forced to "ignore"), end the run: exit 1, nothing written;
    the last one is not blamed on the learning rate."""
    import freespace.engine.adapt as adapt_module

    extra = ["--epochs", "2"]
    if case.startswith("lr"):
        extra += ["--lr", case.split()[1]]
        needles = ("adapt diverged", "nothing was written", "--lr")
    else:
        monkeypatch.setattr(adapt_module, "pseudo_labels",
                            lambda probs, threshold: np.full(probs.shape, adapt_module.IGNORE, np.uint8))
        monkeypatch.setattr(adapt_module, "round_labels",  # the default: the labels completed by appearance
                            lambda images, *_: (np.full(images.shape[:3], adapt_module.IGNORE, np.uint8), {}))
        needles = ("sure of no pixel", "nothing was written", "--threshold")
    out = tmp_path / "out"
    assert main(_argv(model, frames, out, *extra)) == 1
    err = _last_error(capsys)
    assert all(n in err for n in needles), err
    if not case.startswith("lr"):
        assert "--lr" not in err, err
    assert not out.exists()


def test_the_guard_is_relative_and_watches_the_loss() -> None:
    """The road share may not halve or double whatever ``max_drift`` (0.3 never acts on frames with 20 % road);
    a loss whose recent mean is an order of magnitude above its first step's (and above ln 2) is a divergence,
    a noisy one that stays low is not."""
    from freespace.engine.adapt import AdaptSettings, CollapseError, _check_loss, _guard
    from freespace.errors import TrainingError

    settings = AdaptSettings()
    assert issubclass(CollapseError, TrainingError) and CollapseError("x").exit_code == 1
    for now, words in ((0.09, "less than half"), (0.013, "less than half"), (0.45, "more than twice")):
        with pytest.raises(CollapseError, match=words):
            _guard({"road_share": 0.2}, {"road_share": now}, settings, "in round 1")
    for now in (0.15, 0.25, 0.39):
        _guard({"road_share": 0.2}, {"road_share": now}, settings, "in round 1")
    # dusk: the teacher's light-normalised view finds more road than the frames as they are; the student may follow
    _guard({"road_share": 0.05}, {"road_share": 0.15}, settings, "in round 1", view_share=0.1)
    with pytest.raises(CollapseError, match="more than twice"):
        _guard({"road_share": 0.05}, {"road_share": 0.15}, settings, "in round 1")
    with pytest.raises(CollapseError, match="from 0.04 .* to 14.4"):
        _check_loss([0.04, 0.05, 43.0], "in round 2")
    with pytest.raises(CollapseError, match="diverged"):
        _check_loss([0.04] + [2e12] * 10, "in round 1")
    _check_loss([0.04, 0.2, 0.05, 0.3, 0.1], "in round 1")  # noisy, below ln 2
    _check_loss([0.3, 2.0, 0.4], "in round 1")  # a spike, less than 10× on average


# --- 2. what cannot be learnt is refused before training, naming the frames or the checkpoint ---------------------


@pytest.mark.parametrize("case", ["sure of no pixel", "road everywhere", "no road", "overflowing weights",
                                  "infinitesimal std", "black frames", "sky frames", "1x1 frames",
                                  "one tiny frame among good ones"])
def test_what_cannot_be_learnt_is_refused_before_training(case: str, model: Path, frames: Path, tmp_path: Path,
                                                          no_training: list[int], capsys) -> None:
    """A model sure of no pixel (nothing to learn from), one that finds road everywhere or nowhere, a checkpoint
    whose outputs are not finite, frames with no road (black, sky: the published model finds none) and frames too
    small to show one: one line, exit 2, before any round, naming the frames or the checkpoint, never --lr."""
    folder, inputs = model, frames
    if case == "sure of no pixel":
        folder, needles = _variant(model, tmp_path / "m", _classifier((0.0, 0.0))), ("sure of no pixel", "--input")
    elif case == "road everywhere":
        folder, needles = _variant(model, tmp_path / "m", _classifier((0.0, 10.0))), ("road nearly everywhere",)
    elif case == "no road":
        folder, needles = _variant(model, tmp_path / "m", _classifier((10.0, 0.0))), ("finds no road", "--input")
    elif case in ("overflowing weights", "infinitesimal std"):
        def change(ckpt: dict) -> None:
            if case == "overflowing weights":
                ckpt["state_dict"]["net.classifier.3.weight"].mul_(1e38)
            else:
                ckpt["state_dict"]["net.std"][:] = 1e-45
        folder = _variant(model, tmp_path / "m", change)
        needles = ("model.ckpt gives non-finite outputs", str(tmp_path / "m"))
    elif case in ("black frames", "sky frames"):
        folder = PUBLISHED
        colour = (0, 0, 0) if case == "black frames" else (135, 190, 235)
        inputs = _frames(tmp_path / "in", 20, image=np.tile(np.array(colour, np.uint8), (96, 320, 1)))
        needles = ("finds no road", "--input")
    elif case == "1x1 frames":
        inputs, needles = _frames(tmp_path / "in", 20, image=np.zeros((1, 1, 3), np.uint8)), ("1×1 pixels",)
    else:
        inputs = _frames(tmp_path / "in", 22)
        write_image(inputs / "f005.png", np.zeros((8, 20, 3), np.uint8))
        needles = ("frame f005 is 20×8 pixels", "--input")
    out = tmp_path / "out"
    err = refused(capsys, _argv(folder, inputs, out))
    assert all(n in err for n in needles) and "--lr" not in err, err
    assert no_training == [] and not out.exists()


@pytest.mark.parametrize("size", [[0, 96], [-32, 96], [100000, 100000], [32.0, 96.0], "32x96", [32], [32, 96, 3],
                                  [True, 96], None, [32, 2**40]])
def test_the_checkpoint_image_size_is_checked_where_it_is_read(size, model: Path, frames: Path, tmp_path: Path,
                                                               capsys) -> None:
    """An ``image_size`` that is not two ints in 32…MAX_IMAGE_SIDE is one line naming the checkpoint, before any
    frame is read (no cv2.error, no 30 GB allocation)."""
    def change(ckpt: dict) -> None:
        if size is None:
            del ckpt["hyper_parameters"]["image_size"]
        else:
            ckpt["hyper_parameters"]["image_size"] = size
    folder = _variant(model, tmp_path / "m", change)
    err = refused(capsys, _argv(folder, frames, tmp_path / "out"))
    assert str(folder / "model.ckpt") in err and "image size" in err, err
    import freespace

    with pytest.raises(CorruptFileError, match="image size"):
        freespace.adapt(folder, frames, tmp_path / "py", epochs=1, threads=1, progress=False)
    assert not (tmp_path / "out").exists() and not (tmp_path / "py").exists()


@pytest.mark.parametrize("name, value", [("lr", None), ("epochs", None), ("threshold", None), ("batch_size", None),
                                         ("ema", None), ("max_drift", None), ("seed", None), ("progress", None),
                                         ("model", None), ("inputs", None), ("out", None), ("out", ""),
                                         ("source", 5), ("epochs", "4"), ("lr", math.nan), ("epochs", True),
                                         ("minutes", 0), ("threads", 1000), ("threads", 0), ("threads", 2.0),
                                         ("batch_size", 1024), ("threshold", 1.5)])
def test_every_library_argument_is_checked_before_any_work(name: str, value, model: Path, frames: Path,
                                                           tmp_path: Path, monkeypatch) -> None:
    """``freespace.adapt`` checks each argument (type and bounds, as the command line's; None only for minutes,
    source and threads): an InvalidOptionError naming the parameter, before the model folder is even looked at."""
    import freespace
    import freespace.engine.adapt as adapt_module

    def started(*args, **kwargs):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(adapt_module, "_model_folder", started)
    args = {"model": model, "inputs": frames, "out": tmp_path / "out"}
    kwargs = {"epochs": 1, "threads": 1, "progress": False}
    (args if name in args else kwargs)[name] = value
    with pytest.raises(InvalidOptionError) as caught:
        freespace.adapt(args["model"], args["inputs"], args["out"], **kwargs)
    named = "input" if name == "inputs" else name  # adapt's messages name the frames input, as the flag does
    assert str(caught.value).startswith(f"{named} ") or f" {named} " in str(caught.value), str(caught.value)
    assert len(str(caught.value).splitlines()) == 1 and not (tmp_path / "out").exists()


# --- 3. messages name what is wrong --------------------------------------------------------------------------------


@pytest.mark.parametrize("flag", ["--source", "--input"])
def test_a_missing_frame_source_is_named_by_its_flag(flag: str, model: Path, frames: Path, tmp_path: Path,
                                                     capsys) -> None:
    argv = _argv(model, frames, tmp_path / "out", "--source", str(frames))
    argv[argv.index(flag) + 1] = str(tmp_path / "nope")
    err = refused(capsys, argv)
    assert f"{flag} not found: {tmp_path / 'nope'}" in err, err
    empty = tmp_path / "empty"
    empty.mkdir()
    argv[argv.index(flag) + 1] = str(empty)
    assert f"{flag} {empty} holds no frames" in refused(capsys, argv)


# --- 4. bounded resources -------------------------------------------------------------------------------------------


def test_threads_batch_and_source_frames_are_bounded(model: Path, frames: Path, tmp_path: Path, capsys) -> None:
    """No 2,000 threads, no 256 source frames a step: the batch is 2…64 frames and at most MAX_STEP_PIXELS
    pixels of views (fewer frames for a model of many pixels), a quarter of them source frames; the frames kept
    of a set are bounded in bytes too."""
    from freespace.engine import adapt as A
    from freespace.limits import max_workers

    for flag, value in (("--batch-size", "1024"), ("--batch-size", "65"), ("--threads", str(max_workers() + 1))):
        assert flag in refused(capsys, _argv(model, frames, tmp_path / "out", flag, value))
    assert max(A._batch_split(b, True)[1] for b in range(2, A.MAX_ADAPT_BATCH + 1)) == A.MAX_ADAPT_BATCH // 4
    settings = A.AdaptSettings(batch_size=64)
    assert A._check_memory((192, 640), settings, Path("m")) == A.MAX_FRAMES  # every bound met
    # the published model (288×960): views of 288×480, at most 30 a step; every frame bound met
    assert A._check_memory((288, 960), A.AdaptSettings(batch_size=30), Path("m")) == A.MAX_FRAMES
    with pytest.raises(InvalidOptionError, match="at most 30 a step"):
        A._check_memory((288, 960), settings, Path("m"))
    with pytest.raises(InvalidOptionError, match="at most 17 a step"):
        A._check_memory((384, 1248), settings, Path("m"))
    with pytest.raises(InvalidOptionError, match="runs at 4096×4096"):
        A._check_memory((4096, 4096), A.AdaptSettings(batch_size=2), Path("m"))
    kept = A._check_memory((1024, 2048), A.AdaptSettings(batch_size=2), Path("m"))
    assert A.MIN_FRAMES <= kept < A.MAX_FRAMES and kept * 5 * 1024 * 2048 <= A.MAX_FRAME_BYTES


# --- 5. nothing of the model folder is read from outside it, and the card escapes what it quotes -------------------


def test_the_card_title_comes_only_from_a_regular_readme_bounded_and_escaped(tmp_path: Path) -> None:
    """A README.md that is a link (to a system file) or a pipe gives no title (the folder's name instead); a
    5 MB first line gives at most MAX_TITLE_CHARS characters; HTML and Markdown in it are escaped."""
    from freespace.engine.adapt_io import MAX_TITLE_CHARS, _title

    def folder(name: str) -> Path:
        (tmp_path / name).mkdir()
        return tmp_path / name

    secret = tmp_path / "secret.txt"
    secret.write_text("SECRET first line\n")
    linked = folder("linked")
    (linked / "README.md").symlink_to(secret)
    assert _title(linked) == "linked"
    piped = folder("piped")
    os.mkfifo(piped / "README.md")
    assert _title(piped) == "piped"  # opened without blocking, and refused
    huge = folder("huge")
    (huge / "README.md").write_text("# " + "x" * 5_000_000 + "\nmore\n")
    assert len(_title(huge)) <= MAX_TITLE_CHARS
    html = folder("html")
    (html / "README.md").write_text("# <script>alert(1)</script> [click](http://x) **b** `c` | d\n")
    title = _title(html)
    assert "<script>" not in title and "&lt;script&gt;" in title
    assert "\\[click\\]" in title and "\\*\\*b\\*\\*" in title and "\\`c\\`" in title and "\\|" in title


def test_a_linked_readme_puts_nothing_of_its_target_in_the_new_card(model: Path, frames: Path, tmp_path: Path,
                                                                    capsys) -> None:
    import shutil

    folder = tmp_path / "linked-model"
    folder.mkdir()
    shutil.copy(model / "model.ckpt", folder / "model.ckpt")
    secret = tmp_path / "secret.txt"
    secret.write_text("# SECRET <b>first</b> line\n")
    (folder / "README.md").symlink_to(secret)
    assert main(_argv(folder, frames, tmp_path / "out")) == 0
    card = (tmp_path / "out" / "README.md").read_text()
    assert "SECRET" not in card and "**linked-model**" in card


# --- 6. a long input is thinned to as many frames as allowed ------------------------------------------------------


def test_a_long_input_keeps_as_many_frames_as_allowed_evenly_spread(frames: Path, tmp_path: Path,
                                                                    monkeypatch) -> None:
    """1,050 frames at most 1,000 keep 1,000 (not 525), the first and the last among them, evenly spread; a folder
    and a video alike, and a video whose container understates its frames keeps no more than allowed."""
    from freespace.engine.adapt_io import read_frames, thin
    from freespace.io.codecs import read_image
    from freespace.io.video import VideoWriter

    for total, most in ((1050, 1000), (1999, 1000), (2001, 1000), (24, 10), (11, 10), (10, 10), (5, 10)):
        kept = thin(total, most)
        assert len(kept) == min(total, most) and kept[0] == 0 and kept[-1] == total - 1, (total, most)
        gaps = np.diff(kept)
        assert gaps.min() >= 1 and gaps.max() - gaps.min() <= 1, (total, most)
    assert len(read_frames(frames, SIZE, max_frames=13).names) == 13
    video = tmp_path / "drive.mp4"
    with VideoWriter(video, fps=10) as writer:
        for i in range(12):
            writer.write(read_image(frames / f"f{i:03d}.png"))
    clip = read_frames(video, SIZE, max_frames=7)
    assert len(clip.names) == 7 and clip.names[0] == "drive_000000" and clip.names[-1] == "drive_000011"
    import dataclasses

    import freespace.io.video as video_module

    opened = video_module.open_frames
    monkeypatch.setattr(video_module, "open_frames", lambda *a, **k: dataclasses.replace(opened(*a, **k), count=2))
    short = read_frames(video, SIZE, max_frames=7)  # a container that says 2 frames: still at most 7, spread over 12
    assert len(short.names) == 7 and short.names[0] == "drive_000000" and short.total == 12


# --- 7. no input is read from inside --out and then replaced --------------------------------------------------------


@pytest.mark.parametrize("flag", ["--input", "--source"])
def test_a_frame_that_links_into_out_is_refused(flag: str, model: Path, frames: Path, tmp_path: Path,
                                                capsys) -> None:
    """A folder of frames one of which is a link to a file in ``--out`` (an earlier adapt's picture): the file is an
    input inside the output; refused before anything is read or replaced."""
    out = tmp_path / "out"
    assert main(_argv(model, frames, out)) == 0
    capsys.readouterr()
    picture = out / "before_after.jpg"
    before = picture.read_bytes()
    cam = tmp_path / "cam"
    cam.mkdir()
    for p in sorted(frames.iterdir()):
        (cam / p.name).symlink_to(p)
    (cam / "f999.jpg").symlink_to(picture)
    argv = _argv(model, frames, out, "--source", str(frames))
    argv[argv.index(flag) + 1] = str(cam)
    err = refused(capsys, argv)
    assert "lies inside --out" in err and flag in err, err
    assert picture.read_bytes() == before and json.loads((out / "summary.json").read_text())["frames"] == 24
