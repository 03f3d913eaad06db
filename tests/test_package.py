"""The installed package: version, exception hierarchy, command line."""

from __future__ import annotations

import re
import importlib.metadata
import pickle
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import blendtrack
from blendtrack import _blendtrack

REPO_ROOT = Path(__file__).resolve().parents[1]


def _pyproject_version() -> str:
    with open(REPO_ROOT / "pyproject.toml", "rb") as f:
        version: str = tomllib.load(f)["project"]["version"]
    return version


def _run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "blendtrack.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def test_version_of_native_module_matches_pyproject() -> None:
    # __version__ is compiled in from Cargo.toml; a mismatch means the two
    # manifests disagree or the extension is a stale build.
    assert blendtrack.__version__ == _pyproject_version()
    assert blendtrack.__version__ == importlib.metadata.version("blendtrack")


def test_public_names_are_the_native_ones() -> None:
    # Every public name is the native object itself, except the Python-side
    # helpers of blendtrack.simulation.
    from blendtrack import simulation

    for name in blendtrack.__all__:
        if hasattr(simulation, name) and not hasattr(_blendtrack, name) or name == "simulate":
            assert getattr(blendtrack, name) is getattr(simulation, name), name
        else:
            assert getattr(blendtrack, name) is getattr(_blendtrack, name), name


@pytest.mark.parametrize(
    "cls",
    [blendtrack.ConfigError, blendtrack.PathError, blendtrack.SimulationError, blendtrack.InputError],
)
def test_exception_hierarchy(cls: type[Exception]) -> None:
    assert cls.__mro__[1] is blendtrack.BlendtrackError
    assert blendtrack.BlendtrackError.__mro__[1] is Exception
    with pytest.raises(blendtrack.BlendtrackError, match="bad key 'x'"):
        raise cls("bad key 'x'")


def test_input_error_is_also_a_value_error() -> None:
    assert issubclass(blendtrack.InputError, ValueError)
    err = blendtrack.InputError("argument `x` has 2 entries")
    assert type(err).__module__ == "blendtrack"
    copy = pickle.loads(pickle.dumps(err))
    assert type(copy) is blendtrack.InputError


def test_exceptions_are_siblings() -> None:
    assert not issubclass(blendtrack.ConfigError, blendtrack.PathError)
    assert not issubclass(blendtrack.PathError, blendtrack.SimulationError)
    assert not issubclass(blendtrack.SimulationError, blendtrack.ConfigError)


def test_exceptions_are_public_and_pickle() -> None:
    err = blendtrack.PathError("row 3: NaN coordinate")
    assert type(err).__module__ == "blendtrack"
    assert repr(err) == "PathError('row 3: NaN coordinate')"
    copy = pickle.loads(pickle.dumps(err))
    assert type(copy) is blendtrack.PathError
    assert copy.args == ("row 3: NaN coordinate",)


def test_cli_version_prints_the_version() -> None:
    result = _run_cli("version")
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"{blendtrack.__version__}\n"
    assert result.stderr == ""


def test_cli_unknown_subcommand_is_a_one_line_error() -> None:
    result = _run_cli("no-such-command")
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("blendtrack: error:")
    assert "no-such-command" in lines[0]
    assert "Traceback" not in result.stderr


def test_cli_without_subcommand_is_a_one_line_error() -> None:
    result = _run_cli()
    assert result.returncode == 2
    assert len(result.stderr.splitlines()) == 1, result.stderr


def test_cli_main_returns_exit_code() -> None:
    from blendtrack.cli import main

    assert main(["version"]) == 0
    with pytest.raises(SystemExit) as exc_info:
        main(["--no-such-flag"])
    assert exc_info.value.code == 2


def test_configs_pickle_with_their_values() -> None:
    """Configs cross process boundaries (batch workers, run_scenario's child)."""
    c = blendtrack.ControllerConfig(lat_blend_factor=0.37, preferred_speed=12.345678901234).replace(use_path_widths=False)
    back = pickle.loads(pickle.dumps(c))
    assert back == c and back.preferred_speed == 12.345678901234 and back.use_path_widths is False
    assert back != blendtrack.ControllerConfig()
    v = blendtrack.VehicleParams(wheelbase_m=2.9)
    assert pickle.loads(pickle.dumps(v)) == v != blendtrack.VehicleParams()


def test_the_stub_lists_exactly_the_config_keys_the_core_has() -> None:
    """The .pyi types each config key for users; the keys themselves are
    defined once, in the core, and the stub must follow them."""
    import ast
    from pathlib import Path

    import blendtrack

    stub = ast.parse((Path(blendtrack.__file__).parent / "_blendtrack.pyi").read_text())
    for cls, instance in (("ControllerConfig", blendtrack.ControllerConfig()), ("VehicleParams", blendtrack.VehicleParams())):
        node = next(n for n in stub.body if isinstance(n, ast.ClassDef) and n.name == cls)
        typed = {n.target.id for n in node.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)}
        assert typed == set(instance.to_dict()), f"{cls}: stub {sorted(typed ^ set(instance.to_dict()))}"


def test_with_alpha_sets_the_blend_factor_or_the_automatic_mode_and_refuses_the_rest() -> None:
    auto_cfg = blendtrack.ControllerConfig(lat_blend_factor=0.2).with_alpha("auto")
    assert (auto_cfg.alpha_mode, auto_cfg.lat_blend_factor) == ("auto", 0.2)
    fixed = auto_cfg.with_alpha(0.7)
    assert (fixed.alpha_mode, fixed.lat_blend_factor) == ("fixed", 0.7)
    assert fixed.with_alpha(None) == fixed
    for bad, words in (("Auto", "or \"auto\", got 'Auto'"), (True, "got True"), ([1], "got [1]"), (1.5, "lat_blend_factor")):
        with pytest.raises(blendtrack.ConfigError, match=re.escape(words)):
            fixed.with_alpha(bad)
