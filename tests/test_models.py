"""The six networks, tested alike (parametrised over the registry): shapes, odd sizes, gradients,
state_dict round trip, ONNX export with onnxruntime parity; then what is particular to each."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest
import torch

from freespace.errors import FreespaceError, InvalidOptionError
from freespace.models import IGNORE_INDEX, create_model, list_models, main_logits

MODELS = list_models()


def _target(n: int, h: int, w: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    t = (torch.rand(n, h // 8, w // 8, generator=g) > 0.5).long()
    t = torch.nn.functional.interpolate(t[:, None].float(), size=(h, w), mode="nearest")[:, 0].long()
    t[:, :4] = IGNORE_INDEX
    return t


def test_registry() -> None:
    assert MODELS == ["deeplabv3plus", "denseaspp", "dupsampling", "gscnn", "segnet", "unet"]
    with pytest.raises(InvalidOptionError, match="choose one of deeplabv3plus, denseaspp"):
        create_model("fcn")
    with pytest.raises(InvalidOptionError, match="preset"):
        create_model("segnet", preset="huge")
    with pytest.raises(InvalidOptionError, match="bad option"):
        create_model("segnet", colour="red")


@pytest.mark.parametrize("name", MODELS)
def test_eval_logits_at_input_size(name: str) -> None:
    torch.manual_seed(0)
    model = create_model(name, num_classes=3).eval()
    with torch.no_grad():
        for h, w in ((64, 96), (70, 101)):  # a multiple of 32, and odd sizes padded inside
            y = model(torch.rand(2, 3, h, w))
            assert isinstance(y, torch.Tensor) and y.shape == (2, 3, h, w) and torch.isfinite(y).all()
    with pytest.raises(InvalidOptionError, match="N×3×H×W"):
        model(torch.rand(3, 64, 64))


@pytest.mark.parametrize("name", MODELS)
def test_train_step_reaches_every_parameter(name: str) -> None:
    torch.manual_seed(0)
    model = create_model(name).train()
    x = torch.rand(2, 3, 64, 96)
    out = model(x)
    logits = main_logits(out)
    assert logits.shape == (2, 2, 64, 96)
    if isinstance(out, dict):
        assert next(iter(out)) == "logits"
    losses = model.loss(out, _target(2, 64, 96))
    assert set(losses) >= {"total", "seg"} and torch.isfinite(losses["total"])
    losses["total"].backward()
    missing = [n for n, p in model.named_parameters() if p.requires_grad and (p.grad is None or not p.grad.abs().sum())]
    assert not missing, missing[:5]
    # one SGD step lowers the loss on the same batch
    opt = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.9)
    opt.step()
    before = losses["total"].item()
    for _ in range(3):
        opt.zero_grad()
        loss = model.loss(model(x), _target(2, 64, 96))["total"]
        loss.backward()
        opt.step()
    assert loss.item() < before


@pytest.mark.parametrize("name", MODELS)
def test_state_dict_round_trip(name: str) -> None:
    torch.manual_seed(0)
    model = create_model(name).eval()
    buf = io.BytesIO()
    torch.save(model.state_dict(), buf)
    buf.seek(0)
    torch.manual_seed(1)
    other = create_model(name).eval()
    other.load_state_dict(torch.load(buf, weights_only=True))
    x = torch.rand(1, 3, 64, 64)
    with torch.no_grad():
        torch.testing.assert_close(other(x), model(x))


@pytest.mark.parametrize("name", MODELS)
def test_onnx_export_matches_pytorch(name: str, tmp_path) -> None:
    ort = pytest.importorskip("onnxruntime")
    torch.manual_seed(0)
    model = create_model(name).eval()
    path = tmp_path / f"{name}.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, (torch.rand(1, 3, 64, 96),), str(path), dynamo=False, opset_version=17,
                          input_names=["image"], output_names=["logits"],
                          dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}, "logits": {0: "n", 2: "h", 3: "w"}})
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    for shape in ((2, 3, 96, 128), (1, 3, 75, 110)):  # another size, and one that needs padding inside
        x = torch.rand(*shape)
        got = session.run(None, {"image": x.numpy()})[0]
        with torch.no_grad():
            want = model(x).numpy()
        assert got.shape == want.shape == (shape[0], 2) + shape[2:]
        np.testing.assert_allclose(got, want, atol=2e-4, rtol=1e-3)


# --- particular to one network -----------------------------------------------------------------------

def test_segnet_unpools_with_the_pooling_indices() -> None:
    model = create_model("segnet")
    assert model.encoder[0][0][0].out_channels == 16 and len(model.encoder) == 5
    paper = create_model("segnet", preset="paper")
    assert [b[0][0].out_channels for b in paper.encoder] == [64, 128, 256, 512, 512]
    assert sum(len(b) for b in paper.encoder) == 13  # VGG16's 13 convolutions


def test_segnet_takes_vgg16_bn_weights(monkeypatch: pytest.MonkeyPatch) -> None:
    import segmentation_models_pytorch as smp

    real = smp.encoders.get_encoder
    torch.manual_seed(3)
    vgg = real("vgg16_bn", weights=None)
    monkeypatch.setattr(smp.encoders, "get_encoder", lambda name, weights=None, **kw: vgg)  # stands in for a download
    model = create_model("segnet", preset="paper", encoder_weights="imagenet")
    src = [m for m in vgg.modules() if isinstance(m, torch.nn.Conv2d)]
    dst = [m for b in model.encoder for m in b.modules() if isinstance(m, torch.nn.Conv2d)]
    assert len(src) == len(dst) == 13
    assert all(torch.equal(a.weight, b.weight) for a, b in zip(src, dst))
    # the first block computes what VGG's first block computes (conv biases folded into batch norm)
    vgg.eval(), model.eval()
    for m in vgg.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
    model = create_model("segnet", preset="paper", encoder_weights="imagenet").eval()
    x = torch.rand(1, 3, 32, 32)
    with torch.no_grad():
        torch.testing.assert_close(model.encoder[0](x), vgg.features[:6](x), atol=1e-5, rtol=1e-4)
    with pytest.raises(InvalidOptionError, match="full-width"):
        create_model("segnet", encoder_weights="imagenet")


def test_segnet_unpool_is_max_unpool() -> None:
    from freespace.models.segnet import _unpool

    x = torch.rand(2, 3, 8, 12)
    y, idx = torch.nn.functional.max_pool2d(x, 2, 2, return_indices=True)
    assert torch.equal(_unpool(y, idx), torch.nn.functional.max_unpool2d(y, idx, 2, 2))


def test_denseaspp_rates_and_output_stride() -> None:
    model = create_model("denseaspp", preset="paper")
    rates = [u[-2].dilation[0] for u in model.units]
    assert rates == [3, 6, 12, 18, 24]
    assert [u[-2].out_channels for u in model.units] == [64] * 5 and model.units[0][1].out_channels == 128
    with torch.no_grad():
        feats = model.features(torch.rand(1, 3, 64, 96))
    assert feats.shape[-2:] == (8, 12)  # output stride 8


def test_dupsampling_reconstruction_from_labels() -> None:
    model = create_model("dupsampling", compressed_dim=16)
    labels = [_target(2, 64, 96) for _ in range(2)]
    clean = [torch.where(t == IGNORE_INDEX, 0, t) for t in labels]
    kept = model.fit_reconstruction(clean)
    assert 0.5 < kept <= 1.0
    W = model.reconstruction
    torch.testing.assert_close(W.T @ W, torch.eye(16), atol=1e-4, rtol=0)
    # a label coded and decoded through W comes back (these labels are blocks of 8 px: few components)
    from freespace.models.dupsampling import label_patches

    p, _ = label_patches(clean[0], 2, 16)
    mean = model.patch_mean[None, :, None, None]
    z = torch.einsum("nphw,pk->nkhw", p - mean, W)
    back = torch.einsum("nkhw,pk->nphw", z, W) + mean
    decoded = torch.nn.functional.pixel_shuffle(back, 16).argmax(1)
    assert (decoded == clean[0]).float().mean() > 0.97


def test_gscnn_edges_and_losses() -> None:
    from freespace.models.gscnn import label_boundaries

    t = torch.zeros(1, 8, 8, dtype=torch.long)
    t[:, :, 4:] = 1
    t[:, 0] = IGNORE_INDEX
    edges, valid = label_boundaries(t)
    assert edges[0, 4].tolist() == [False, False, False, True, True, False, False, False]
    assert not valid[0, :2].any() and valid[0, 4].all()
    model = create_model("gscnn").train()
    out = model(torch.rand(1, 3, 64, 64))
    assert out["edges"].shape == (1, 1, 64, 64)
    losses = model.loss(out, _target(1, 64, 64))
    assert {"edge", "attention", "dual"} <= set(losses)


def test_pretrained_weights_fail_clearly_offline(monkeypatch: pytest.MonkeyPatch) -> None:
    import segmentation_models_pytorch as smp

    def offline(*args, **kwargs):
        raise OSError("Network is unreachable")

    monkeypatch.setattr(smp.encoders, "get_encoder", offline)
    for name in ("gscnn", "dupsampling"):
        with pytest.raises(FreespaceError, match="encoder_weights=None"):
            create_model(name, encoder_weights="imagenet")
