"""tests/commandline.py: a command run in the test's process leaves what a new interpreter would show, and nothing
of itself behind."""

import signal
import sys
import warnings

import rlcore.__main__ as entry
from commandline import ROOT, command


def test_a_command_in_process_shows_warnings_as_an_interpreter_would_and_leaves_nothing_behind(monkeypatch):
    seen = {}

    def main(argv):
        seen["argv"], seen["sys.argv"] = argv, list(sys.argv)
        warnings.warn("shown", UserWarning)
        warnings.warn("hidden outside __main__", DeprecationWarning)
        signal.signal(signal.SIGTERM, signal.default_int_handler)  # as rlcore.cli.run_command does
        print("out")
        return 2

    monkeypatch.setattr(entry, "main", main)
    handler, argv = signal.getsignal(signal.SIGTERM), list(sys.argv)
    result = command("rlcore", "evaluate", 5, check=False)
    assert (result.returncode, result.stdout) == (2, "out\n")
    assert "UserWarning: shown" in result.stderr and "hidden" not in result.stderr
    assert seen == {"argv": ["evaluate", "5"], "sys.argv": [str(ROOT / "rlcore" / "__main__.py"), "evaluate", "5"]}
    assert signal.getsignal(signal.SIGTERM) is handler and sys.argv == argv
