"""Shared test set-up: the runner's cache of scenarios SUMO loaded without
error lives in a temporary folder for the test session (never the user's);
``build_net`` makes a small network with SUMO's netconvert."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

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


@pytest.fixture
def build_net() -> Callable[..., Path]:
    """``build(folder, nodes, edges, connections=None)``: writes the nodes,
    edges (and connections) XML under ``folder`` (created), runs SUMO's
    netconvert on them without turnarounds and returns ``folder/n.net.xml``;
    netconvert's complaint fails the test."""
    from blendtrack.sumo.connection import sumo_binary

    def build(folder: Path, nodes: str, edges: str, connections: str | None = None) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "n.nod.xml").write_text(nodes)
        (folder / "n.edg.xml").write_text(edges)
        cmd = [str(Path(sumo_binary(False)).with_name("netconvert")), "-n", str(folder / "n.nod.xml"), "-e", str(folder / "n.edg.xml"),
               "-o", str(folder / "n.net.xml"), "--no-turnarounds", "true"]
        if connections is not None:
            (folder / "n.con.xml").write_text(connections)
            cmd += ["-x", str(folder / "n.con.xml")]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return folder / "n.net.xml"

    return build
