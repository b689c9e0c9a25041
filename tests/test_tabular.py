import numpy as np
import pytest

from rlcore.checkpoint import load_checkpoint
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.logger import read_csv
from rlcore.tabular import (
    Config, TabularPolicy, epsilon_greedy, greedy_policy, linear_schedule, q_learning_update,
    sarsa_update, td_target, train,
)

CLIFF = dict(alpha=0.5, gamma=1.0, epsilon_start=0.1, epsilon_end=0.1, epsilon_decay_steps=0)


def test_td_target_bootstraps_except_at_termination():
    assert td_target(1.0, 10.0, 0.9, terminated=False) == pytest.approx(10.0)
    assert td_target(1.0, 10.0, 0.9, terminated=True) == 1.0


def test_q_learning_update_by_hand():
    Q = np.array([[0.0, 0.0], [2.0, 5.0]])
    # target = -1 + 0.5 * max(2, 5) = 1.5; error = 1.5 - 0 ; Q <- 0 + 0.1 * 1.5
    err = q_learning_update(Q, s=0, a=1, r=-1.0, s_next=1, terminated=False, alpha=0.1, gamma=0.5)
    assert err == pytest.approx(1.5)
    assert Q[0, 1] == pytest.approx(0.15)
    assert Q[1].tolist() == [2.0, 5.0]  # nothing else moved


def test_sarsa_uses_the_next_action_taken_not_the_max():
    Q = np.array([[0.0, 0.0], [2.0, 5.0]])
    sarsa_update(Q, s=0, a=1, r=-1.0, s_next=1, a_next=0, terminated=False, alpha=0.1, gamma=0.5)
    assert Q[0, 1] == pytest.approx(0.1 * (-1.0 + 0.5 * 2.0))
    sarsa_update(Q, s=0, a=0, r=3.0, s_next=1, a_next=1, terminated=True, alpha=1.0, gamma=0.5)
    assert Q[0, 0] == 3.0  # terminal: just the reward


def test_epsilon_greedy_frequencies():
    rng = np.random.default_rng(0)
    q = np.array([0.0, 1.0, 0.5])
    picks = np.array([epsilon_greedy(q, 0.3, rng) for _ in range(20_000)])
    freq = np.bincount(picks, minlength=3) / len(picks)
    np.testing.assert_allclose(freq, [0.1, 0.8, 0.1], atol=0.015)
    assert {epsilon_greedy(np.zeros(4), 0.0, rng) for _ in range(200)} == {0, 1, 2, 3}  # ties at random


def test_linear_schedule():
    assert linear_schedule(1.0, 0.1, 100, 0) == 1.0
    assert linear_schedule(1.0, 0.1, 100, 50) == pytest.approx(0.55)
    assert linear_schedule(1.0, 0.1, 100, 1000) == pytest.approx(0.1)
    assert linear_schedule(1.0, 0.1, 0, 0) == 0.1


def test_q_learning_finds_the_optimal_policy_of_deterministic_frozenlake():
    result = train("FrozenLake-v1", Config(env_kwargs={"is_slippery": False}), steps=15_000, seed=0)
    env = make_env("FrozenLake-v1", is_slippery=False)
    returns = evaluate_policy(TabularPolicy(result.Q), env, episodes=3, max_steps=100)
    assert returns.tolist() == [1.0, 1.0, 1.0]
    # optimal means shortest: 6 steps, so the start value is gamma^5 once converged
    steps, s = 0, env.reset(seed=0)[0]
    done = False
    while not done:
        s, _, done, _, _ = env.step(int(greedy_policy(result.Q)[s]))
        steps += 1
    assert steps == 6


def _greedy_return(Q, env_id="CliffWalking-v1"):
    return evaluate_policy(TabularPolicy(Q), make_env(env_id), episodes=1, max_steps=100)[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cliff_walking_sarsa_is_safe_and_q_learning_is_optimal(seed):
    q = train("CliffWalking-v1", Config(method="q-learning", **CLIFF), steps=20_000, seed=seed)
    s = train("CliffWalking-v1", Config(method="sarsa", **CLIFF), steps=20_000, seed=seed)
    assert _greedy_return(q.Q) == -13.0                 # along the cliff edge: the optimal path
    assert -100 < _greedy_return(s.Q) < -13.0           # a longer, safer path that still reaches the goal
    # ... but while exploring, Q-learning falls off more and earns less per episode
    assert s.episode_returns[-200:].mean() > q.episode_returns[-200:].mean()


def test_same_seed_gives_the_same_table():
    a = train("Taxi-v4", Config(), steps=3_000, seed=5)
    b = train("Taxi-v4", Config(), steps=3_000, seed=5)
    c = train("Taxi-v4", Config(), steps=3_000, seed=6)
    np.testing.assert_array_equal(a.Q, b.Q)
    assert not np.array_equal(a.Q, c.Q)


def test_run_folder_contents_and_resume(tmp_path):
    out = tmp_path / "run"
    first = train("FrozenLake-v1", Config(checkpoint_every=500), steps=2_000, seed=1, out=out)
    for name in ("config.json", "meta.json", "progress.csv", "checkpoint.pt"):
        assert (out / name).exists()
    ckpt = load_checkpoint(out / "checkpoint.pt")
    assert ckpt["step"] == 2_000 and ckpt["complete"]
    np.testing.assert_array_equal(ckpt["q"].numpy(), first.Q)
    rows = read_csv(out / "progress.csv")
    assert rows["step"][-1] <= 2_000 and len(rows["episode"]) == len(first.episode_returns)
    # training further with a larger budget continues from the checkpoint
    more = train("FrozenLake-v1", Config(checkpoint_every=500), steps=3_000, seed=1, out=out)
    assert more.steps == 3_000 and load_checkpoint(out / "checkpoint.pt")["step"] == 3_000
    assert read_csv(out / "progress.csv")["episode"][0] == 1  # appended, not restarted
    with pytest.raises(ValueError, match="holds a q-learning run"):
        train("FrozenLake-v1", Config(method="sarsa"), steps=10, seed=1, out=out)


def test_ctrl_c_stops_at_the_end_of_the_step_with_a_checkpoint(tmp_path, monkeypatch):
    import os
    import signal

    import rlcore.tabular as tab

    calls = {"n": 0}
    real = tab.q_learning_update

    def interrupting(*args, **kwargs):  # Ctrl-C in the middle of step 1234, before its update
        calls["n"] += 1
        if calls["n"] == 1234:
            os.kill(os.getpid(), signal.SIGINT)
        return real(*args, **kwargs)

    monkeypatch.setattr(tab, "q_learning_update", interrupting)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            train("FrozenLake-v1", Config(checkpoint_every=10_000), steps=5_000, seed=0, out=tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    # the step Ctrl-C came in ran to its end, update included: the checkpoint is between two steps
    assert ckpt["step"] == 1234 and not ckpt["complete"] and calls["n"] == 1234


def test_non_tabular_env_is_a_clear_error():
    with pytest.raises(ValueError, match="discrete states and actions"):
        train("CartPole-v1", steps=10)


def test_bad_config():
    with pytest.raises(ValueError, match="method"):
        Config(method="expected-sarsa")
    with pytest.raises(ValueError, match="alpha"):
        Config(alpha=0.0)


def test_value_iteration_on_deterministic_frozenlake_by_hand():
    from rlcore.tabular import best_return, transition_model, value_iteration

    R, M = transition_model("FrozenLake-v1", is_slippery=False)
    assert R.shape == (16, 4) and M.shape == (16, 4, 16)
    assert R[14, 2] == 1.0 and M[14, 2].sum() == 0.0  # RIGHT from 14 reaches the goal and ends
    Q = value_iteration(R, M, gamma=0.9, sweeps=50)
    # the shortest path is 6 steps, rewarded only at the end: V(start) = 0.9^5
    assert Q[0].max() == pytest.approx(0.9**5)
    assert best_return("FrozenLake-v1", 5, is_slippery=False) == 0.0   # 5 steps are not enough
    assert best_return("FrozenLake-v1", 6, is_slippery=False) == 1.0
    assert best_return("CliffWalking-v1", 100) == -13.0


def test_learned_table_agrees_with_value_iteration_on_the_greedy_path():
    from rlcore.tabular import transition_model, value_iteration

    R, M = transition_model("CliffWalking-v1")
    Q_star = value_iteration(R, M, gamma=1.0, sweeps=200)
    learned = train("CliffWalking-v1", Config(method="q-learning", **CLIFF), steps=20_000, seed=0).Q
    env = make_env("CliffWalking-v1")
    s, _ = env.reset(seed=0)
    for _ in range(13):
        a = int(greedy_policy(learned)[s])
        assert Q_star[s, a] == Q_star[s].max()  # every greedy step is an optimal action
        s, _, done, _, _ = env.step(a)
    assert done


def test_grid_map_reads_the_cliff_from_the_transitions():
    from rlcore.tabular import grid_map

    cliff = grid_map("CliffWalking-v1")
    assert cliff.shape == (4, 12) and cliff[3, 0] == "S" and cliff[3, 11] == "G"
    assert (cliff[3, 1:11] == "C").all() and (cliff[:3] == "F").all()
    lake = grid_map("FrozenLake-v1")
    assert lake[0, 0] == "S" and lake[3, 3] == "G" and (lake == "H").sum() == 4


def test_a_run_resumed_from_a_checkpoint_at_an_episodes_last_step_is_the_uninterrupted_run(
        tmp_path, interrupt_at_first_checkpoint):
    import rlcore.tabular as tab

    config = dict(env_kwargs={"is_slippery": True})
    whole = train("FrozenLake-v1", Config(**config), steps=600, seed=3, out=tmp_path / "whole")
    end = int(whole.episode_end_steps[2])  # the third episode's last step
    interrupt_at_first_checkpoint(tab)
    with pytest.raises(KeyboardInterrupt):
        train("FrozenLake-v1", Config(checkpoint_every=end, **config), steps=600, seed=3, out=tmp_path / "cut")
    ckpt = load_checkpoint(tmp_path / "cut" / "checkpoint.pt")
    assert ckpt["step"] == end and ckpt["episode"] == 3  # the episode that ended at the checkpoint's step counts
    again = train("FrozenLake-v1", Config(checkpoint_every=end, **config), steps=600, seed=3, out=tmp_path / "cut")
    np.testing.assert_array_equal(again.Q, whole.Q)
    logs = [read_csv(tmp_path / name / "progress.csv") for name in ("whole", "cut")]
    for column in ("episode", "step", "episode_return"):
        assert logs[1][column].tolist() == logs[0][column].tolist(), column  # every episode once, as uninterrupted
