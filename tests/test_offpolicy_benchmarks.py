"""benchmarks/offpolicy_flops.py (the FLOPs of a TD3 and a SAC update, and where an update's time goes) and
benchmarks/offpolicy_vs_sb3.py (rlcore's TD3 and SAC against SB3's), on tiny networks."""
import pytest
import torch


@pytest.fixture
def flops(script_module):
    return script_module("benchmarks/offpolicy_flops.py")


@pytest.fixture
def versus(script_module):
    return script_module("benchmarks/offpolicy_vs_sb3.py")


def test_the_hand_count_of_a_tiny_update(flops):
    # Pendulum: obs 3, act 1; hidden (8, 8); batch 4. Critic 4 -> 8 -> 8 -> 1: k*n = 32, 64, 8 (sum 104);
    # TD3 actor 3 -> 8 -> 8 -> 1: 24, 64, 8 (sum 96). 2 B = 8 FLOPs per multiply-add term of a layer.
    assert flops.forward_flops([4, 8, 8, 1], 4) == 8 * 104
    assert flops.backward_flops([4, 8, 8, 1], 4) == 8 * 104 + 8 * 72               # weights; inputs below layer 1
    assert flops.backward_flops([4, 8, 8, 1], 4, weights=False, input_grad=True) == 8 * 104
    td3 = flops.update_flops("td3", 3, 1, hidden=(8, 8), batch=4)
    assert td3["target"] == 8 * (96 + 2 * 104)
    assert td3["critics"] == 2 * 8 * (104 + 104 + 72)
    assert td3["actor"] == 8 * (96 + 104 + 104 + 96 + 72) / 2                     # every 2nd step
    assert td3["total"] == td3["target"] + td3["critics"] + td3["actor"] == 8800
    # SAC's actor: body 3 -> 8 -> 8, heads 8 -> 1 twice, as one layer of 2 outputs: 24, 64, 16 (sum 104)
    sac = flops.update_flops("sac", 3, 1, hidden=(8, 8), batch=4)
    assert sac["actor"] == 8 * (104 + 2 * 104 + 2 * 104 + 104 + 80) and sac["total"] == 12608
    # the critics' weight gradients in the actor's backward pass (as SB3 computes them): Q_1 every 2nd step / both
    assert flops.update_flops("td3", 3, 1, (8, 8), 4, frozen_critics=False)["total"] == 8800 + 8 * 104 / 2
    assert flops.update_flops("sac", 3, 1, (8, 8), 4, frozen_critics=False)["total"] == 12608 + 2 * 8 * 104
    with pytest.raises(ValueError, match="td3 or sac"):
        flops.update_flops("ddpg", 3, 1)


@pytest.mark.parametrize("algo", ["td3", "sac"])
def test_torch_counts_what_the_hand_count_says_on_rlcores_own_update(flops, algo):
    learn, minibatch = flops.capture_learn(algo, "Pendulum-v1", hidden=(8, 8), batch=4)
    assert flops.counted_flops(learn, minibatch) == flops.update_flops(algo, 3, 1, hidden=(8, 8), batch=4)["total"]


def test_the_issues_figures_are_the_count_with_the_critics_weight_gradients(flops):
    for (algo, env_id), gflop in flops.ISSUE_GFLOP.items():
        obs_dim, act_dim = flops.TASKS[env_id]
        # to the issue's two decimals ("about"): 0.433, 0.860, 0.655 and 1.335
        assert abs(flops.update_flops(algo, obs_dim, act_dim, frozen_critics=False)["total"] / 1e9 - gflop) < 0.0051
        assert flops.update_flops(algo, obs_dim, act_dim)["total"] / 1e9 < 0.97 * gflop


def test_kernel_split_replays_every_operation_of_an_update(flops):
    learn, minibatch = flops.capture_learn("sac", "Pendulum-v1", hidden=(8, 8), batch=4)
    split = flops.kernel_split(learn, minibatch, rounds=1, calls=2)
    assert split["ops_not_replayed"] == 0 and split["ops_matmul"] > 0 and split["ops_adam"] == 2  # critics, actor
    assert split["seconds_update"] > 0 and all(split[f"seconds_{k}"] >= 0 for k in ("matmul", "adam", "other"))
    assert split["seconds_overhead"] == pytest.approx(
        split["seconds_update"] - split["seconds_matmul"] - split["seconds_adam"] - split["seconds_other"])
    assert flops.op_kind(torch.ops.aten.baddbmm.default) == "matmul"
    assert flops.op_kind(torch.ops.aten.relu.default) == "other"


def test_fresh_copies_keep_shape_strides_and_values(flops):
    x = torch.arange(6.0).reshape(2, 3)
    y, (z,) = flops._fresh((x.t(), [x.expand(2, 2, 3)]))
    assert y.stride() == x.t().stride() and torch.equal(y, x.t()) and y.data_ptr() != x.data_ptr()
    assert z.shape == (2, 2, 3) and z.stride() == (0, 3, 1)            # an expanded view stays one


def test_both_sides_get_the_same_settings(versus):
    td3 = versus.rlcore_config(versus.settings("td3", 1000))
    assert (td3.hidden, td3.batch_size, td3.actor_lr, td3.critic_lr, td3.policy_delay) == ((256, 256), 256, 1e-3,
                                                                                          1e-3, 2)
    assert (td3.target_policy_noise, td3.target_noise_clip, td3.exploration_noise) == (0.2, 0.5, 0.1)
    assert (td3.learning_starts, td3.eval_every, td3.normalize_obs, td3.clipped_double_q) == (1000, 0, False, True)
    sac = versus.rlcore_config(versus.settings("sac", 500))
    assert (sac.hidden, sac.batch_size, sac.alpha, sac.autotune, sac.target_entropy) == ((256, 256), 256, 1.0, True,
                                                                                        None)
    assert (sac.actor_lr, sac.critic_lr, sac.alpha_lr, sac.learning_starts) == (3e-4, 3e-4, 3e-4, 500)
    with pytest.raises(ValueError, match="td3"):
        versus.settings("ddpg", 1000)


@pytest.mark.parametrize("algo", ["td3", "sac"])
def test_an_rlcore_run_says_where_its_time_went_and_puts_everything_back(versus, algo):
    from rlcore import offpolicy

    module = __import__(f"rlcore.{algo}", fromlist=["OffPolicyLoop"])
    loop, sample = module.OffPolicyLoop, offpolicy.Minibatch.__dict__["sample"]
    cfg = {**versus.settings(algo, 20), "hidden": [8, 8], "batch_size": 8, "buffer_size": 100}
    seconds = versus.rlcore_run("Pendulum-v1", 30, 0, cfg)
    split = versus.SPLITS["rlcore"][-1]
    assert split["seconds_total"] == seconds and split["learning_steps"] == 11 and 0 < split["cpu_seconds_total"]
    parts = ("networks", "simulator", "acting", "replay_sampling", "rest")
    assert sum(split[f"share_{k}"] for k in parts) == pytest.approx(1.0)
    assert all(split[f"seconds_{k}"] > 0 for k in parts[:4])
    assert module.OffPolicyLoop is loop and offpolicy.Minibatch.__dict__["sample"] is sample
    pooled = versus.pooled([split, split])
    assert pooled["seconds_total"] == 2 * seconds and pooled["share_networks"] == pytest.approx(split["share_networks"])


@pytest.mark.parametrize("algo", ["td3", "sac"])
def test_an_sb3_run_with_the_same_settings(versus, algo):
    pytest.importorskip("stable_baselines3")
    cfg = {**versus.settings(algo, 20), "hidden": [8, 8], "batch_size": 8, "buffer_size": 100}
    versus.sb3_run("Pendulum-v1", 30, 0, cfg)
    split = versus.SPLITS["sb3"][-1]
    assert split["learning_steps"] == 10 and split["seconds_networks"] > 0 and split["seconds_simulator"] > 0


@pytest.mark.parametrize("algo", ["td3", "sac"])
def test_sb3s_update_is_the_count_with_the_critics_weight_gradients(flops, algo):
    pytest.importorskip("stable_baselines3")
    hand = flops.update_flops(algo, 3, 1, hidden=(8, 8), batch=4, frozen_critics=False)["total"]
    assert flops.sb3_counted_flops(algo, "Pendulum-v1", hidden=(8, 8), batch=4) == hand
