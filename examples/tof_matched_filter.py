"""A time-of-flight matched-filter model: an example of a model benchmarked
from outside the package (config: examples/tof.yaml; docs/models.md).

The idea differs from the paper's four, which learn their filters: here the
filters are fixed and physical. A hidden object adds a three-bounce return,
a pulse-shaped bump at the optical path wall -> object -> wall, to every
zone's background-subtracted histogram. The optimal detector of a known
pulse in white noise is its matched filter, so each zone is correlated with
a fixed bank of Gaussian pulses; from each response the model reads three
features:

- the peak time (a soft arg-max over the bins, in units of the histogram
  length): the zone's path length to the object, which locates it;
- the peak height and the response's energy (signed log1p): how much of the
  object the zone sees, which carries its size and shape.

A small MLP maps the features of every zone and filter to the outputs. Only
the MLP learns (about 10k parameters for 3x3 zones).

Factory contract (denali_pipe.train.registry): factory(task, n_outputs,
input_shape (n, n, T)) -> nn.Module taking (B, n, n, T) and giving
(B, n_outputs).
"""

from __future__ import annotations

import torch
from torch import nn

# Filter widths (Gaussian sigma) in bins of 3/128 m optical path. The sensor's
# pulse is ~1.2 bins (sigma) with a tail; a plate's extent spreads its return:
# an 8 in (0.2 m) plate tilted to the wall spans up to ~2 x 0.1 m of path,
# ~8 bins. The bank covers the pulse alone, a small and a large plate.
SIGMAS_BINS = (1.5, 3.0, 6.0)
# Sharpness of the soft arg-max on a response standardised per zone and
# filter: 4 standard deviations of margin weigh the peak ~e^4 above the floor.
SOFTMAX_SHARPNESS = 4.0
HIDDEN = 64
FEATURES_PER_FILTER = 3  # peak time, peak height, energy


def pulse_bank(sigmas: tuple[float, ...]) -> torch.Tensor:
    """(K, 1, L) unit-energy Gaussian pulses, L odd and covering +-3 sigma of the widest."""
    half = int(3 * max(sigmas) + 0.5)
    t = torch.arange(-half, half + 1, dtype=torch.float32)
    bank = torch.stack([torch.exp(-0.5 * (t / s) ** 2) for s in sigmas])
    return (bank / bank.norm(dim=1, keepdim=True))[:, None, :]


def signed_log(x: torch.Tensor) -> torch.Tensor:
    return torch.sign(x) * torch.log1p(x.abs())


class MatchedFilterNet(nn.Module):
    """(B, n, n, T) counts -> (B, K*3, n*n) matched-filter features, batch-normalised
    per filter and feature over the batch and the zones -> flattened -> MLP -> (B, n_out).

    The features have different units (a fraction of the histogram, logs of
    counts), hence the normalisation; it pools the zones as well as the batch,
    like the paper's models pool time, so a training batch of one sample is
    fine (of one sample and one zone, see `forward`). No dropout: on the location head, whose outputs sit ~1 m from zero,
    dropping hidden units moves the output by more than the spread of the
    labels (a few cm on the test data), and the model did not beat the mean."""

    def __init__(self, n: int, bins: int, n_out: int):
        super().__init__()
        self.register_buffer("bank", pulse_bank(SIGMAS_BINS))  # fixed: not a parameter
        self.register_buffer("time", torch.linspace(0.0, 1.0, bins))
        channels = len(SIGMAS_BINS) * FEATURES_PER_FILTER
        self.norm = nn.BatchNorm1d(channels)
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(channels * n * n, HIDDEN),
            nn.GELU(),
            nn.Linear(HIDDEN, HIDDEN),
            nn.GELU(),
            nn.Linear(HIDDEN, n_out),
        )

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """(B, K*3, n*n): per filter the peak time, peak height and energy of every zone."""
        b, n, _, bins = x.shape
        zones = x.reshape(b * n * n, 1, bins)
        r = nn.functional.conv1d(zones, self.bank, padding=self.bank.shape[-1] // 2)  # (B*Z, K, T)
        z = (r - r.mean(-1, keepdim=True)) / (r.std(-1, keepdim=True) + 1e-6)
        weights = torch.softmax(SOFTMAX_SHARPNESS * z, dim=-1)
        peak_time = (weights * self.time).sum(-1)
        peak = signed_log(r.amax(-1))
        energy = torch.log1p(r.square().mean(-1))
        f = torch.stack([peak_time, peak, energy], dim=-1)  # (B*Z, K, 3)
        return f.reshape(b, n * n, -1).transpose(1, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        f = self.features(x)
        if self.training and f.shape[0] * f.shape[-1] == 1:
            # One sample of one zone (the jitter sweep's centre zone, in an
            # epoch's last batch of one) is one value per channel, which
            # cannot be batch-normalised: use the running statistics.
            self.norm.eval()
            f = self.norm(f)
            self.norm.train()
            return self.head(f)
        return self.head(self.norm(f))


def tof_matched_filter(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> nn.Module:
    """The registry factory: one MatchedFilterNet per task (the same for all three)."""
    n, _, bins = input_shape
    return MatchedFilterNet(n, bins, n_outputs)
