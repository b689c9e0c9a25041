"""Batch Renormalization (Ioffe 2017, "Batch Renormalization: Towards Reducing Minibatch Dependence in
Batch-Normalized Models"), the normalization CrossQ puts in its critics and actor (chapter 9).

Batch normalization scales each feature of a minibatch B = {x_1, ..., x_m} by the minibatch's own statistics:

    mu_B = (1/m) sum_i x_i,    sigma_B = sqrt((1/m) sum_i (x_i - mu_B)^2 + eps),    x^_i = (x_i - mu_B) / sigma_B

and keeps running averages mu, sigma^2 for evaluation, where there may be no batch. Training and evaluation then
normalize by different numbers. Batch *re*normalization corrects training toward the running statistics:

    r = clip(sigma_B / sigma, 1/r_max, r_max),    d = clip((mu_B - mu) / sigma, -d_max, d_max)   (no gradient)
    x^_i = (x_i - mu_B) / sigma_B * r + d

With r and d unclipped, x^_i = (x_i - mu) / sigma exactly: the running statistics. Clipped, a batch far from them
moves the output only so much. Both are treated as constants, so the gradient is batch norm's. Then
y_i = gamma x^_i + beta, as in batch norm. The running statistics move toward each batch's:

    mu <- mu + momentum (mu_B - mu),    sigma^2 <- sigma^2 + momentum (s_B^2 - sigma^2)

with s_B^2 the unbiased variance (1/(m-1)) sum_i (x_i - mu_B)^2, as ``torch.nn.BatchNorm1d`` keeps it. For its
first ``warmup`` training batches the layer is plain batch norm (r = 1, d = 0): the running statistics start at
mu = 0, sigma^2 = 1 and mean nothing yet. In evaluation mode (``module.eval()``) it normalizes by mu and sigma alone.

A layer may hold several independent groups of features: ``groups = 2`` normalizes an input of shape (2, m, f), the
two critics of a twin critic at once, each with its own statistics, gamma and beta.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from torch import nn


# [brn-batch-statistics]
def batch_statistics(x: torch.Tensor, eps: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(mu_B, sigma_B) over the batch dimension (the second to last): the mean, and sqrt(biased variance + eps)."""
    mean = x.mean(dim=-2, keepdim=True)
    return mean, (x.var(dim=-2, keepdim=True, unbiased=False) + eps).sqrt()
# [/brn-batch-statistics]


# [brn-corrections]
def renorm_corrections(batch_mean: torch.Tensor, batch_std: torch.Tensor, running_mean: torch.Tensor,
                       running_std: torch.Tensor, r_max: float, d_max: float) -> tuple[torch.Tensor, torch.Tensor]:
    """r = clip(sigma_B / sigma, 1/r_max, r_max) and d = clip((mu_B - mu) / sigma, -d_max, d_max), as constants
    (no gradient flows through them)."""
    r = (batch_std / running_std).clamp(1.0 / r_max, r_max)
    d = ((batch_mean - running_mean) / running_std).clamp(-d_max, d_max)
    return r.detach(), d.detach()


def renormalize(x: torch.Tensor, batch_mean: torch.Tensor, batch_std: torch.Tensor, r: torch.Tensor,
                d: torch.Tensor) -> torch.Tensor:
    """x^ = (x - mu_B) / sigma_B * r + d. With r = 1 and d = 0 this is batch norm."""
    return (x - batch_mean) / batch_std * r + d
# [/brn-corrections]


# [brn-running]
def update_running(running_mean: torch.Tensor, running_var: torch.Tensor, x: torch.Tensor,
                   momentum: float) -> None:
    """mu <- mu + momentum (mu_B - mu) and sigma^2 <- sigma^2 + momentum (s_B^2 - sigma^2), in place, with s_B^2
    the batch's unbiased variance."""
    with torch.no_grad():
        running_mean.lerp_(x.mean(dim=-2, keepdim=True), momentum)
        running_var.lerp_(x.var(dim=-2, keepdim=True, unbiased=True), momentum)
# [/brn-running]


class BatchRenorm(nn.Module):
    """Batch renormalization of ``features`` features (in ``groups`` independent groups): plain batch norm for the
    first ``warmup`` training batches, renormalized after; the running statistics in evaluation mode. Its state
    (running mean and variance, and ``batches``, the training batches seen) is in ``state_dict`` and so in every
    checkpoint: a resumed run goes on where the warm-up was.

    Defaults are CrossQ's (and sb3-contrib's): momentum 0.01, eps 0.001, warm-up 100,000 batches, r_max 3, d_max 5.
    """

    def __init__(self, features: int, groups: int | None = None, momentum: float = 0.01, eps: float = 1e-3,
                 warmup: int = 100_000, r_max: float = 3.0, d_max: float = 5.0):
        super().__init__()
        shape = (1, features) if groups is None else (groups, 1, features)
        self.momentum, self.eps, self.warmup, self.r_max, self.d_max = momentum, eps, warmup, r_max, d_max
        self.weight = nn.Parameter(torch.ones(shape))   # gamma
        self.bias = nn.Parameter(torch.zeros(shape))    # beta
        self.register_buffer("running_mean", torch.zeros(shape))
        self.register_buffer("running_var", torch.ones(shape))
        self.register_buffer("batches", torch.tensor(0, dtype=torch.long))
        self.track = True
        """Update the running statistics in training mode (``batch_stats(..., track=False)`` turns it off)."""
        self.train(False)  # kept in evaluation mode; batch_stats() switches it to training for a pass

    # [brn-forward]
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training:  # evaluation: the running statistics alone
            x_hat = (x - self.running_mean) / (self.running_var + self.eps).sqrt()
        else:
            batch_mean, batch_std = batch_statistics(x, self.eps)
            if self.batches < self.warmup:  # warm-up: batch norm
                x_hat = (x - batch_mean) / batch_std
            else:
                r, d = renorm_corrections(batch_mean, batch_std, self.running_mean,
                                          (self.running_var + self.eps).sqrt(), self.r_max, self.d_max)
                x_hat = renormalize(x, batch_mean, batch_std, r, d)
            if self.track:
                update_running(self.running_mean, self.running_var, x, self.momentum)
                self.batches += 1
        return self.weight * x_hat + self.bias
    # [/brn-forward]

    def extra_repr(self) -> str:
        return (f"features={self.weight.shape[-1]}, groups={self.weight.shape[0] if self.weight.dim() == 3 else None}"
                f", momentum={self.momentum}, eps={self.eps}, warmup={self.warmup}, r_max={self.r_max}, "
                f"d_max={self.d_max}")


@contextlib.contextmanager
def batch_stats(module: nn.Module, track: bool = True) -> Iterator[None]:
    """Inside, the :class:`BatchRenorm` layers of ``module`` normalize by the batch and update their running
    statistics (training mode); outside, they use the running statistics (evaluation mode), which is how a
    network with them is kept. ``track=False``: the running statistics and warm-up count are left as they are, a
    read-only look at what training would compute."""
    layers = [m for m in module.modules() if isinstance(m, BatchRenorm)]
    for m in layers:
        m.train(True)
        m.track = track
    try:
        yield
    finally:
        for m in layers:
            m.train(False)
            m.track = True
