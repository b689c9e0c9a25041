"""CSV progress logs: one row per episode or per update, readable by any spreadsheet.

A resumed run appends to its log instead of starting over, so an interrupted run loses nothing.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np


class CSVLogger:
    """Append rows of numbers to a CSV file; the first row fixes the columns.

    >>> with CSVLogger("progress.csv") as log:          # doctest: +SKIP
    ...     log.log(step=1000, episode_return=-12.0)
    """

    def __init__(self, path: str | os.PathLike, fieldnames: list[str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fieldnames = list(fieldnames) if fieldnames else None
        if self.path.exists() and self.path.stat().st_size > 0:
            with self.path.open(newline="") as f:
                header = next(csv.reader(f), None)
            if header:
                if self.fieldnames is not None and header != self.fieldnames:
                    raise ValueError(f"{self.path} has columns {header}, not {self.fieldnames}")
                self.fieldnames = header
        self._file = self.path.open("a", newline="")
        self._writer = None
        if self.fieldnames is not None:
            self._writer = csv.DictWriter(self._file, fieldnames=self.fieldnames)
            if self._file.tell() == 0:
                self._writer.writeheader()

    def log(self, **row: Any) -> None:
        """Write one row (and flush, so a crash or Ctrl-C keeps it)."""
        if self._writer is None:
            self.fieldnames = list(row)
            self._writer = csv.DictWriter(self._file, fieldnames=self.fieldnames)
            self._writer.writeheader()
        unknown = set(row) - set(self.fieldnames)
        if unknown:
            raise ValueError(f"columns {sorted(unknown)} are not in {self.path}'s header {self.fieldnames}")
        self._writer.writerow({k: _cell(v) for k, v in row.items()})
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> CSVLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def drop_rows_after(path: str | os.PathLike, step: int, column: str = "step") -> int:
    """Remove the rows of a log whose ``column`` is past ``step``; returns how many were removed.

    A run resumed from a checkpoint taken at ``step`` redoes what came after it; without this, those
    steps would appear twice in its log.
    """
    path = Path(path)
    if not path.exists():
        return 0
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        header, rows = reader.fieldnames, list(reader)
    if not header or column not in header:
        return 0
    keep = [r for r in rows if not r[column] or float(r[column]) <= step]
    if len(keep) == len(rows):
        return 0
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=header)
        writer.writeheader()
        writer.writerows(keep)
    os.replace(tmp, path)
    return len(rows) - len(keep)


def _cell(value: Any) -> Any:
    if isinstance(value, (np.generic,)):
        return value.item()
    if isinstance(value, float):
        return repr(value)
    return value


def read_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a progress log into one NumPy array per column (numbers where every cell is a number)."""
    with Path(path).open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    columns: dict[str, np.ndarray] = {}
    for name in rows[0]:
        values = [r[name] for r in rows]
        try:
            columns[name] = np.array([float(v) for v in values])
        except ValueError:
            columns[name] = np.array(values)
    return columns
