"""rlcore.launch: torchrun's command line for DPPO, a process's children and a torchrun worker's rank."""

import os
import subprocess
import sys
import time

import pytest

from rlcore.cli import overrides
from rlcore.dppo import Config, build_parser
from rlcore.launch import TORCHRUN, child_pids, torchrun_command, worker_rank


def test_torchrun_command_is_what_rlcore_dppo_parses():
    cmd = torchrun_command(2, "Pendulum-v1", 60_000, 3, "runs/x", {"n_steps": 256, "gamma": 0.95},
                           restarts=1, extra=["--dump-params", "p"])
    assert cmd[:3] == TORCHRUN and cmd[3:6] == ["--standalone", "--nproc_per_node=2", "--max-restarts=1"]
    assert cmd[6:8] == ["-m", "rlcore.dppo"]
    args = build_parser().parse_args(cmd[8:])
    assert (args.env, args.steps, args.seed, args.out, args.no_progress) == ("Pendulum-v1", 60_000, 3, "runs/x", True)
    assert overrides(Config, args.set) == {"n_steps": 256, "gamma": 0.95} and args.dump_params == "p"
    assert "--no-progress" not in torchrun_command(1, "CartPole-v1", 10, 0, "o", progress=True)
    with pytest.raises(ValueError):
        torchrun_command(0, "CartPole-v1", 10, 0, "o")


def test_several_nodes_meet_at_a_rendezvous_instead_of_standalone():
    cmd = torchrun_command(1, "Pendulum-v1", 1_000, 0, "runs/x", nodes=2, rendezvous="host0:29400", job_id="hc1")
    assert cmd[3:9] == ["--nnodes=2", "--rdzv-backend=c10d", "--rdzv-endpoint=host0:29400", "--rdzv-id=hc1",
                        "--nproc_per_node=1", "--max-restarts=0"]
    assert "--standalone" not in cmd and build_parser().parse_args(cmd[11:]).out == "runs/x"
    with pytest.raises(ValueError, match="rendezvous endpoint"):
        torchrun_command(1, "Pendulum-v1", 1_000, 0, "o", nodes=2)


def test_children_and_rank_of_a_started_process():
    code = ("import subprocess, sys, time; "
            "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)']); time.sleep(30)")
    parent = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, "RANK": "7"})
    try:
        deadline = time.time() + 20
        while not child_pids(parent.pid) and time.time() < deadline:
            time.sleep(0.05)
        kids = child_pids(parent.pid)
        assert len(kids) == 1
        assert worker_rank(parent.pid) == 7 and worker_rank(kids[0]) == 7   # the child inherits the environment
        assert worker_rank(os.getpid()) == int(os.environ.get("RANK", -1))
        assert child_pids(kids[0]) == []
    finally:
        for pid in child_pids(parent.pid):
            os.kill(pid, 9)
        parent.kill()
        parent.wait()
