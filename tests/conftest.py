"""Shared test set-up: the runner's cache of scenarios SUMO loaded without
error lives in a temporary folder for the test session (never the user's)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True, scope="session")
def _private_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    old = os.environ.get("BLENDTRACK_CACHE_DIR")
    os.environ["BLENDTRACK_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    yield
    if old is None:
        os.environ.pop("BLENDTRACK_CACHE_DIR", None)
    else:
        os.environ["BLENDTRACK_CACHE_DIR"] = old
