"""The four benchmark models of the DENALI paper (supplement §11.2, docs/deviations.md),
and their factories: entries of the model registry like any user model
(`registry`, config `train.models`).

Every model takes a batch of histograms `x` of shape (B, n, n, bins): n zones per
side (3 or 8) and `bins` time bins (128, or fewer where the pipeline crops the
time axis), and returns (B, C): C = 2 for location (x, y in metres), the number
of shape classes for shape (logits), 2 for size (logits for 4inch, 8inch).

The layers follow the reference release layer for layer, including its quirks,
so that `n_params` for 3x3x128 input gives the paper's Table 10 (except the
Transformer size model, see `Transformer`). GELU, dropout 0.1 and PyTorch's
default initialisation throughout. Every size that depends on the input (MLP
and shallow 3D CNN flatten widths, Transformer positional encoding) is computed
from (n, bins) at construction, so parameter counts are known before any forward.
"""

from __future__ import annotations

import copy
import math

import torch
from torch import nn

from denali_pipe.train.registry import N_LOCATION_OUTPUTS

DROPOUT = 0.1


def n_params(model: nn.Module) -> int:
    """Trainable parameters; buffers (BN running statistics) are not parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def _mlp_head(widths: list[int], n_out: int) -> nn.Sequential:
    """Linear+GELU+Dropout for each consecutive pair of `widths`, then Linear(widths[-1], n_out)."""
    layers: list[nn.Module] = []
    for w_in, w_out in zip(widths, widths[1:]):
        layers += [nn.Linear(w_in, w_out), nn.GELU(), nn.Dropout(DROPOUT)]
    return nn.Sequential(*layers, nn.Linear(widths[-1], n_out))


class MLP(nn.Module):
    """Flatten (B, n, n, bins) to (B, n*n*bins) -> 512 -> 256 -> 128 -> (B, n_out)."""

    def __init__(self, n: int, bins: int, n_out: int):
        super().__init__()
        self.net = _mlp_head([n * n * bins, 512, 256, 128], n_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x.flatten(1))


class CNN1d(nn.Module):
    """Zones as channels, convolution along time.

    (B, n, n, bins) -> (B, n*n, bins) -> three Conv1d-BN-GELU blocks
    (n*n -> 128 k5, 128 -> 128 k3, 128 -> 64 k3; 'same' length, no conv bias)
    -> global average over time (B, 64) -> Linear(64, 32)-GELU-Dropout -> Linear(32, n_out).

    `with_out_tanh` adds the reference regressor's `out_tanh` Linear(32, 2). The
    reference defines it but its forward never calls it; it is in the state dict
    and in the paper's parameter count (82,340 = 82,274 + 66), so the location
    model keeps it for a faithful count. It is never called here either and gets
    no gradient.
    """

    H = 128  # hidden channels (h in the supplement)

    def __init__(self, n: int, n_out: int, with_out_tanh: bool = False):
        super().__init__()
        h = self.H
        self.features = nn.Sequential(
            *self._block(n * n, h, 5),
            *self._block(h, h, 3),
            *self._block(h, h // 2, 3),
        )
        self.pool = nn.AdaptiveAvgPool1d(1)
        self.mlp = nn.Sequential(nn.Linear(h // 2, 32), nn.GELU(), nn.Dropout(DROPOUT))
        self.out_linear = nn.Linear(32, n_out)
        if with_out_tanh:
            self.out_tanh = nn.Linear(32, N_LOCATION_OUTPUTS)  # dead layer, see the class docstring

    @staticmethod
    def _block(c_in: int, c_out: int, k: int) -> list[nn.Module]:
        return [nn.Conv1d(c_in, c_out, k, padding=k // 2, bias=False), nn.BatchNorm1d(c_out), nn.GELU()]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.features(x.flatten(1, 2))  # (B, n*n, bins) -> (B, 64, bins)
        return self.out_linear(self.mlp(self.pool(x).squeeze(-1)))


class CNN3dDeep(nn.Module):
    """The reference's location and size 3D CNN (`MediumConv3DOverCRegNet` / `DeepConv3DNet`).

    (B, n, n, bins) -> (B, 1, n, n, bins) -> three Conv3d-BN-GELU blocks, 1 -> 128 -> 128 -> 64,
    kernel (3, 3, 10), 'same' padding (time: 4 before, 5 after), no conv bias
    -> global average (B, 64) -> Linear(64, 32)-GELU-Dropout -> Linear(32, n_out).
    """

    KERNEL = (3, 3, 10)
    H = 128  # hidden channels (h in the supplement)

    def __init__(self, n_out: int):
        super().__init__()
        h = self.H
        self.features = nn.Sequential(
            *self._block(1, h),
            *self._block(h, h),
            *self._block(h, h // 2),
            nn.AdaptiveAvgPool3d(1),
            nn.Flatten(),
        )
        self.head = _mlp_head([h // 2, 32], n_out)

    @classmethod
    def _block(cls, c_in: int, c_out: int) -> list[nn.Module]:
        # The reference's padding="same": for the even time kernel PyTorch puts the
        # extra element after (4 before, 5 after). Padding explicitly is the same
        # operation without PyTorch's warning about the copy it makes.
        pad = nn.ConstantPad3d((4, 5, 1, 1, 1, 1), 0.0)  # (time, width, height), last dim first
        conv = nn.Conv3d(c_in, c_out, cls.KERNEL, bias=False)
        return [pad, conv, nn.BatchNorm3d(c_out), nn.GELU()]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x.unsqueeze(1)))


class CNN3dShallow(nn.Module):
    """The reference's shape 3D CNN (`MediumConv3DOverCNet`): one strided block, wide MLP head.

    (B, n, n, bins) -> (B, 1, n, n, bins) -> Conv3d(1 -> 32, kernel (5, 5, 16),
    stride (2, 2, 4), padding (2, 2, 8), no bias)-BN-GELU -> (B, 32, m, m, t), flattened
    (3x3x128: m = 2, t = 33, 4224 features) -> 512 -> 256 -> 128 -> (B, n_out).
    """

    KERNEL, STRIDE, PADDING = (5, 5, 16), (2, 2, 4), (2, 2, 8)
    CHANNELS = 32

    def __init__(self, n: int, bins: int, n_out: int):
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv3d(1, self.CHANNELS, self.KERNEL, self.STRIDE, self.PADDING, bias=False),
            nn.BatchNorm3d(self.CHANNELS),
            nn.GELU(),
            nn.Flatten(),
        )
        m, _, t = ((size + 2 * p - k) // s + 1 for size, k, s, p in zip((n, n, bins), self.KERNEL, self.STRIDE, self.PADDING))
        self.head = _mlp_head([self.CHANNELS * m * m * t, 512, 256, 128], n_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x.unsqueeze(1)))


class Transformer(nn.Module):
    """Time bins as tokens, zones as token features; a CLS token reads out.

    (B, n, n, bins) -> tokens (B, bins, n*n) -> Linear(n*n, 256) * sqrt(256)
    + learned positional encoding (1, bins, 256), initialised N(0, 0.02)
    -> 4 pre-LN encoder layers (8 heads, FF 1024, GELU) -> final LayerNorm
    -> CLS output (B, 256) -> head -> (B, n_out).

    The reference builds the classifier and the regressor differently, and both
    are kept as they are:
    - classifier (shape, size): CLS is prepended *before* the input LayerNorm and
      dropout; head LayerNorm(256)-Linear(256, 128)-GELU-Dropout-Linear(128, n_out).
    - regressor (location): input LayerNorm and dropout first, then CLS; the head
      has no LayerNorm.
    The CLS token starts at zeros and gets no positional encoding in both.
    The head LayerNorm (512 parameters) is why the rebuilt size model has
    3,229,314 parameters where the paper prints 3,228,802, the regressor's count.
    """

    D_MODEL, N_HEADS, D_FF, N_LAYERS = 256, 8, 1024, 4

    def __init__(self, n: int, bins: int, n_out: int, classifier: bool):
        super().__init__()
        d = self.D_MODEL
        self.classifier = classifier
        self.embed = nn.Linear(n * n, d)
        self.pos = nn.Parameter(torch.empty(1, bins, d).normal_(0.0, 0.02))
        self.cls = nn.Parameter(torch.zeros(1, 1, d))
        self.input_norm = nn.LayerNorm(d)
        self.input_dropout = nn.Dropout(DROPOUT)
        layer = nn.TransformerEncoderLayer(d, self.N_HEADS, self.D_FF, DROPOUT, activation="gelu", batch_first=True, norm_first=True)
        # Nested tensors only apply to post-LN layers; disabling them avoids a warning.
        self.encoder = nn.TransformerEncoder(layer, self.N_LAYERS, norm=nn.LayerNorm(d), enable_nested_tensor=False)
        head_norm = [nn.LayerNorm(d)] if classifier else []
        self.head = nn.Sequential(*head_norm, *_mlp_head([d, 128], n_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        tokens = x.flatten(1, 2).transpose(1, 2)  # (B, bins, n*n)
        h = self.embed(tokens) * math.sqrt(self.D_MODEL) + self.pos  # (B, bins, d)
        cls = self.cls.expand(h.shape[0], -1, -1)
        if self.classifier:
            h = self.input_dropout(self.input_norm(torch.cat([cls, h], dim=1)))
        else:
            h = torch.cat([cls, self.input_dropout(self.input_norm(h))], dim=1)
        return self.head(self.encoder(h)[:, 0])  # (B, bins + 1, d) -> CLS (B, d) -> (B, n_out)


# The factories (registry's contract): factory(task, n_outputs, input_shape (n, n, T)) -> nn.Module.


def mlp(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> nn.Module:
    n, _, bins = input_shape
    return MLP(n, bins, n_outputs)


def cnn1d(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> nn.Module:
    return CNN1d(input_shape[0], n_outputs, with_out_tanh=task == "location")


def cnn3d(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> nn.Module:
    n, _, bins = input_shape
    return CNN3dShallow(n, bins, n_outputs) if task == "shape" else CNN3dDeep(n_outputs)


def transformer(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> nn.Module:
    n, _, bins = input_shape
    return Transformer(n, bins, n_outputs, classifier=task != "location")


# The paper's four by the names config.yaml registers them under.
PAPER_MODELS = {"mlp": mlp, "cnn1d": cnn1d, "cnn3d": cnn3d, "transformer": transformer}


def forward_flops(model: nn.Module, input_shape: tuple[int, int, int]) -> int:
    """Floating-point operations of one sample's forward pass, as torch's
    FlopCounterMode counts them: 2 per multiply-add of the matrix products,
    convolutions and attention; elementwise operations, norms and activations
    are not counted (they are a few % for these models).

    Counted on a copy in training mode: in eval mode PyTorch runs the
    Transformer's encoder layers as one fused kernel that the counter does not
    see, and the copy keeps the model's BatchNorm statistics untouched."""
    from torch.utils.flop_counter import FlopCounterMode

    probe = copy.deepcopy(model).train()
    param = next(probe.parameters(), None)
    x = torch.zeros(1, *input_shape, device=None if param is None else param.device)
    counter = FlopCounterMode(display=False)
    with counter, torch.no_grad():
        probe(x)
    return int(counter.get_total_flops())
