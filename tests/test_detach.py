"""`experiments run ... --detach`: the command goes on in a session of its own when its terminal closes, and its
results land in results/ as a run in the foreground leaves them (issue 57, item 5)."""
import os
import re
import select
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from portable import skip_or_fail

ROOT = Path(__file__).resolve().parents[1]


def wait_for_exit(pid: int, timeout: float) -> bool:
    """Wait for a process that is not our child to end (a pidfd becomes readable when it does)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return True
    try:
        return bool(select.select([fd], [], [], timeout)[0])
    finally:
        os.close(fd)


def test_a_detached_run_outlives_its_terminal_and_lands_its_results(tmp_path):
    if not hasattr(os, "pidfd_open"):
        skip_or_fail("waiting on a detached process needs Linux 5.3 or newer (os.pidfd_open)")
    results, work = tmp_path / "results", tmp_path / "runs"
    command = [sys.executable, "-m", "rlbook", "experiments", "run", "reinforce-a2c-cartpole", "--only", "a2c",
               "--seeds", "0", "--results", str(results), "--work", str(work), "--detach"]
    # the terminal: a shell in a session of its own, which runs the command and then stays, reading its input
    terminal = subprocess.Popen(["bash", "-c", f"{subprocess.list2cmdline(command)} && exec cat"], cwd=ROOT,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True)
    line = terminal.stdout.readline()                     # the command's one line, printed as it returns
    found = re.search(r"as process (\d+).*output: (\S+\.log)", line)
    assert found, line
    pid, log = int(found.group(1)), Path(found.group(2).rstrip(";"))
    try:
        assert os.getsid(pid) == pid != os.getsid(terminal.pid)   # a session of its own, not the terminal's
        assert log.parent == work / "reinforce-a2c-cartpole" and log.exists()
        os.killpg(terminal.pid, signal.SIGHUP)             # the terminal closes: its session gets a hangup
        assert terminal.wait(timeout=30) == -signal.SIGHUP  # ... which ends the shell,
        assert wait_for_exit(pid, timeout=600), "the detached run did not finish"   # not the run
    finally:
        if not wait_for_exit(pid, timeout=0):
            os.kill(pid, signal.SIGTERM)
    seed = results / "reinforce-a2c-cartpole" / "a2c" / "seed-0"
    assert (seed / "policy.pt").exists() and (seed / "eval.csv").exists(), log.read_text()[-2000:]
    assert f"reinforce-a2c-cartpole/a2c/seed-0: done -> {seed}" in log.read_text(), log.read_text()[-2000:]


@pytest.mark.parametrize("args, message", [
    (["run", "reinforce-a2c-cartpole", "--only", "nope"], "has no run 'nope'"),
    (["run", "reinforce-a2c-cartpole", "--seeds", "99"], "has no seed [99]"),
    (["status", "reinforce-a2c-cartpole"], "--detach is for `experiments run`"),
])
def test_what_the_command_would_refuse_is_refused_before_it_detaches(args, message, tmp_path, capsys):
    from rlbook.__main__ import main

    assert main(["experiments", *args, "--work", str(tmp_path / "runs"), "--detach"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "runs").exists()                 # nothing started, no log
