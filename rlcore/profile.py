"""The budget switch every chapter reads.

``RLBOOK_PROFILE=quick`` is what ``pytest --nbval`` uses: every chapter finishes in well under a
minute on two CPU cores. ``RLBOOK_PROFILE=book`` (the default) is what ``jupyter-book build``
uses: full experiments, full-length GIFs.
"""

from __future__ import annotations

import os
from typing import TypeVar

T = TypeVar("T")

PROFILES = ("quick", "book")


def get_profile() -> str:
    """Return the active profile, read from the ``RLBOOK_PROFILE`` environment variable."""
    value = os.environ.get("RLBOOK_PROFILE", "book").strip().lower() or "book"
    if value not in PROFILES:
        raise ValueError(
            f"RLBOOK_PROFILE={value!r} is not a profile; use one of {', '.join(PROFILES)} "
            "(quick: what the tests run, book: what the book build runs)."
        )
    return value


PROFILE = get_profile()


def pick(quick: T, book: T) -> T:
    """Return ``quick`` under the quick profile and ``book`` under the book profile."""
    return quick if get_profile() == "quick" else book
