"""The command lines, run the way the tests need them.

``python -m rlcore ...`` and ``python -m rlbook ...`` are ``sys.exit(main(argv))``. A test that is about what a
command does (its files, its JSON, its refusals, its exit status) calls that same ``main`` here, in the test's
process, with the same ``sys.argv`` the command would see, and its output captured; a new interpreter would add
about two seconds of start-up (importing torch and, at the first optimizer, torch._dynamo) to every call and test
nothing more. A test that is about the process itself (the ``python -m`` entry, signals, a command's recorded
command line) starts one with ``process=True``.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import signal
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Result:
    """What a finished command left: as :class:`subprocess.CompletedProcess` names it."""

    args: list[str]
    returncode: int
    stdout: str
    stderr: str


INTERPRETER_FILTERS = (("default", DeprecationWarning, "__main__"), ("ignore", DeprecationWarning, ""),
                       ("ignore", PendingDeprecationWarning, ""), ("ignore", ImportWarning, ""),
                       ("ignore", ResourceWarning, ""))
"""The warning filters a new interpreter starts with (Python's defaults, no ``-W``), last applied first."""


@contextlib.contextmanager
def warnings_as_a_new_interpreter_shows_them():
    """Inside, warnings are filtered as in a new interpreter and written to ``sys.stderr`` (pytest would otherwise
    record them apart), so that a warning the command would print is in its captured stderr."""
    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    with warnings.catch_warnings():
        warnings.resetwarnings()
        for action, category, module in reversed(INTERPRETER_FILTERS):
            warnings.filterwarnings(action, category=category, module=module)
        warnings.showwarning = show
        yield


def entry(module: str) -> tuple[Callable[[list[str]], int], Path]:
    """The ``main`` that ``python -m <module>`` runs (a package's ``__main__``, else the module's own), and its file."""
    spec = importlib.util.find_spec(module)
    if spec.submodule_search_locations is not None:  # a package: python -m runs its __main__
        module = f"{module}.__main__"
        spec = importlib.util.find_spec(module)
    return importlib.import_module(module).main, Path(spec.origin)


def run_main(package: str, *args: object) -> Result:
    """``python -m <package> *args`` (a package or a module) without a new interpreter: its ``main`` in this
    process, ``sys.argv`` as
    ``python -m`` sets it, warnings shown as a new interpreter shows them, stdout and stderr captured; the signal
    handlers and torch's thread count a command sets are put back after it."""
    import torch

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    main, path = entry(package)
    threads, saved_argv = torch.get_num_threads(), sys.argv
    sys.argv = [str(path), *argv]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
                warnings_as_a_new_interpreter_shows_them():
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse's refusals and --help; a message exits 1, as Python prints it
                code = exc.code
                if code is not None and not isinstance(code, int):
                    print(code, file=sys.stderr)
                    code = 1
    finally:
        sys.argv = saved_argv
        torch.set_num_threads(threads)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    return Result([package, *argv], int(code or 0), out.getvalue(), err.getvalue())


def run_process(package: str, *args: object, timeout: float = 300) -> Result:
    """``python -m <package> *args`` in a new interpreter, as a user's shell runs it."""
    argv = [str(a) for a in args]
    proc = subprocess.run([sys.executable, "-m", package, *argv], capture_output=True, text=True, timeout=timeout)
    return Result([package, *argv], proc.returncode, proc.stdout, proc.stderr)


def command(package: str, *args: object, check: bool = True, process: bool = False) -> Result:
    """Run ``python -m <package> *args`` (in this process unless ``process``); with ``check``, a non-zero exit
    fails the test with the command's stderr."""
    result = (run_process if process else run_main)(package, *args)
    if check and result.returncode != 0:
        raise AssertionError(f"{package} {' '.join(result.args[1:])} failed ({result.returncode}):\n{result.stderr}")
    return result
