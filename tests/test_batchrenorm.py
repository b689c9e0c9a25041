"""rlcore.batchrenorm: batch norm during the warm-up (against torch.nn.BatchNorm1d), Ioffe's equations after it,
running statistics in evaluation mode, groups, and a read-only pass."""

import pytest
import torch

from rlcore.batchrenorm import BatchRenorm, batch_stats, batch_statistics, renorm_corrections, renormalize


def batches(n=6, m=64, f=5, seed=0):
    g = torch.Generator().manual_seed(seed)
    return [torch.randn(m, f, generator=g) * (1 + i) + 3 * i for i in range(n)]


def test_during_the_warm_up_it_is_torch_s_batch_norm_outputs_gradients_and_running_statistics():
    brn = BatchRenorm(5, momentum=0.01, eps=1e-3, warmup=100)
    bn = torch.nn.BatchNorm1d(5, momentum=0.01, eps=1e-3)
    with torch.no_grad():
        for layer in (brn, bn):
            layer.weight.copy_(torch.linspace(0.5, 2, 5))
            layer.bias.copy_(torch.linspace(-1, 1, 5))
    for x in batches():
        xa, xb = x.clone().requires_grad_(), x.clone().requires_grad_()
        with batch_stats(brn):
            ya = brn(xa)
        yb = bn(xb)
        torch.testing.assert_close(ya, yb)
        (ya ** 3).sum().backward()
        (yb ** 3).sum().backward()
        torch.testing.assert_close(xa.grad, xb.grad)
        torch.testing.assert_close(brn.running_mean[0], bn.running_mean)
        torch.testing.assert_close(brn.running_var[0], bn.running_var)
    torch.testing.assert_close(brn.weight.grad[0], bn.weight.grad, rtol=1e-4, atol=1e-3)  # sums of six cubes
    assert int(brn.batches) == 6
    bn.eval()
    x = batches(1, seed=9)[0]
    torch.testing.assert_close(brn(x), bn(x))  # evaluation mode: the running statistics, as BatchNorm1d's


def test_after_the_warm_up_it_follows_ioffe_s_equations():
    brn = BatchRenorm(5, momentum=0.1, eps=1e-3, warmup=2, r_max=1.5, d_max=0.5)
    data = batches(4)
    for x in data[:2]:
        with batch_stats(brn):
            brn(x)
    x = data[3]  # far from the running statistics: the clips bite
    mu, var = brn.running_mean.clone(), brn.running_var.clone()
    with batch_stats(brn):
        y = brn(x)
    mean_b = x.mean(0)
    std_b = (x.var(0, unbiased=False) + 1e-3).sqrt()
    std = (var[0] + 1e-3).sqrt()
    r = (std_b / std).clamp(1 / 1.5, 1.5)
    d = ((mean_b - mu[0]) / std).clamp(-0.5, 0.5)
    assert bool((r == 1.5).any()) and bool((d.abs() == 0.5).all())  # both clipped here
    torch.testing.assert_close(y, (x - mean_b) / std_b * r + d)
    torch.testing.assert_close(brn.running_mean[0], 0.9 * mu[0] + 0.1 * mean_b)
    torch.testing.assert_close(brn.running_var[0], 0.9 * var[0] + 0.1 * x.var(0, unbiased=True))


def test_unclipped_corrections_give_exactly_the_running_statistics_and_are_constants():
    x = torch.randn(32, 4, requires_grad=True)
    mu, sigma = torch.randn(1, 4), torch.rand(1, 4) + 0.5
    mean_b, std_b = batch_statistics(x, 1e-3)
    r, d = renorm_corrections(mean_b, std_b, mu, sigma, r_max=1e6, d_max=1e6)
    assert not r.requires_grad and not d.requires_grad
    torch.testing.assert_close(renormalize(x, mean_b, std_b, r, d), (x - mu) / sigma)


def test_evaluation_mode_uses_the_running_statistics_and_a_read_only_pass_changes_nothing():
    brn = BatchRenorm(3, warmup=0)
    x = torch.randn(16, 3) * 4 + 2
    assert not brn.training  # kept in evaluation mode
    torch.testing.assert_close(brn(x), x / (1 + 1e-3) ** 0.5)  # running mean 0, variance 1: nothing learned yet
    one = brn(x[:1])  # a batch of one is fine in evaluation mode
    assert torch.isfinite(one).all()
    before = {k: v.clone() for k, v in brn.state_dict().items()}
    with batch_stats(brn, track=False):
        brn(x)
    assert all(torch.equal(v, brn.state_dict()[k]) for k, v in before.items())
    with batch_stats(brn):
        brn(x)
    assert not brn.training and int(brn.batches) == 1 and not torch.equal(brn.running_mean, before["running_mean"])


def test_groups_normalize_each_group_by_its_own_statistics():
    grouped = BatchRenorm(4, groups=2, warmup=10)
    singles = [BatchRenorm(4, warmup=10), BatchRenorm(4, warmup=10)]
    x = torch.stack(batches(2, m=20, f=4))
    with batch_stats(grouped):
        y = grouped(x)
    for k, layer in enumerate(singles):
        with batch_stats(layer):
            torch.testing.assert_close(y[k], layer(x[k]))
        torch.testing.assert_close(grouped.running_var[k], layer.running_var)


@pytest.mark.parametrize("field,value", [("bn_momentum", 0.0), ("r_max", 0.5), ("d_max", -1.0), ("bn_eps", 0.0)])
def test_bad_settings_are_refused_in_one_line(field, value):
    from rlcore import crossq

    with pytest.raises(ValueError, match=f"crossq.Config.{field} must be"):
        crossq.Config(**{field: value})
