"""What every command line of rlcore shares (``python -m rlcore`` and ``python -m rlcore.dppo``): argument types
that refuse a bad value in one line, ``--set key=value`` parsing, the exit statuses, and :func:`run_command`, which
runs a command and turns a user's error into one line (the book's ``python -m rlbook`` uses it too).

No library module imports :mod:`rlcore.__main__`; both command lines import this.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import typing
from typing import Any

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def count(low: int):
    """An argparse type: an integer >= ``low``, refused in one line otherwise."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {value}")
        return value
    parse.__name__ = f"integer >= {low}"
    return parse


def seed_list(text: str) -> list[int]:
    """``--seeds 0,1,2``: comma-separated integers >= 0."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 0 such as 0,1, got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 0 such as 0,1, got {text!r}")
    return seeds


def json_object(text: str) -> dict[str, Any]:
    """``--env-kwargs '{"is_slippery": false}'``: a JSON object."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object such as '{{\"is_slippery\": false}}', got {text!r}")
    return value


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed command, ``args.func(args)``, as a process's command: the commit of the code it loaded is noted
    (its runs record it), SIGTERM and Ctrl-C checkpoint and stop, and an error a user can fix (an unknown environment
    or algorithm, a bad checkpoint, no headless GL, a bad value) is one line on stderr and exit status 2."""
    from rlcore.algos import UnknownAlgorithmError
    from rlcore.checkpoint import CheckpointError
    from rlcore.envs import UnknownEnvironmentError
    from rlcore.render import HeadlessGLError
    from rlcore.provenance import loaded_commit
    from rlcore.signals import stop_on_signals

    loaded_commit()
    stop_on_signals()
    try:
        return args.func(args)
    except (UnknownEnvironmentError, UnknownAlgorithmError, CheckpointError, HeadlessGLError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE


class Parser(argparse.ArgumentParser):
    """argparse, but a bad value is one line (``error: ...``) and exit status 2, without the usage block."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(EXIT_USAGE, f"error: {message} (see `{self.prog} --help`)\n")


def parse_value(text: str, annotation: Any) -> Any:
    """Parse a ``--set key=value`` value as JSON where possible (numbers, true/false, dicts).

    A tuple field (``hidden``) also takes one number or comma-separated ones: ``hidden=64`` or ``hidden=64,64``.
    """
    if typing.get_origin(annotation) is tuple and "," in text and not text.lstrip().startswith("["):
        text = f"[{text}]"
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    if annotation in (float, "float") and isinstance(value, int):
        value = float(value)
    if typing.get_origin(annotation) is tuple and not isinstance(value, (list, tuple)):
        value = [value]
    return value


def overrides(config_cls: type, pairs: list[str]) -> dict[str, Any]:
    hints = typing.get_type_hints(config_cls)
    fields = {f.name for f in dataclasses.fields(config_cls)}
    out: dict[str, Any] = {}
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--set expects key=value, got {pair!r}")
        key, text = pair.split("=", 1)
        key = key.strip().replace("-", "_")
        if key not in fields:
            raise ValueError(f"{config_cls.__module__}.Config has no field {key!r}; "
                             f"fields: {', '.join(sorted(fields))}")
        out[key] = parse_value(text, hints.get(key))
    return out


def set_args(overrides: dict[str, Any]) -> list[str]:
    """``["--set", "key=value", ...]`` that :func:`overrides` reads back as ``overrides`` (its inverse).

    Strings go as they are, everything else as JSON (a tuple as a list, ``True`` as ``true``), keys in order.
    """
    def text(value: Any) -> str:
        if isinstance(value, str):
            return value
        return json.dumps(list(value) if isinstance(value, tuple) else value)

    return [arg for key, value in overrides.items() for arg in ("--set", f"{key}={text(value)}")]


def train_command(algo: str, env_id: str, steps: int, seed: int, config: Any) -> str:
    """The ``python -m rlcore train`` line that trains ``config`` (a Config dataclass): only the fields that differ
    from the Config's defaults are set."""
    import shlex

    default = type(config)()
    changed = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)
               if getattr(config, f.name) != getattr(default, f.name)}
    return shlex.join(["python", "-m", "rlcore", "train", algo, "--env", env_id, "--steps", str(steps),
                       "--seed", str(seed), *set_args(changed)])
