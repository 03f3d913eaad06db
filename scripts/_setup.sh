# shellcheck shell=bash
# Shared set-up for scripts/test and scripts/quickstart (sourced, not run).
#
# After `blendtrack_setup`, .venv holds blendtrack installed in editable mode
# with the `dev` extra (test tools + maturin), and the native module
# python/blendtrack/_blendtrack*.so is a release build of the current Rust
# sources. Safe to run any number of times:
# - .venv is created (and its pip upgraded) only when missing;
# - `pip install -e '.[dev]'` runs only when pyproject.toml or the install
#   command changed since the last successful install (their hash is kept in
#   .venv/.blendtrack-install);
# - the native module is rebuilt by `maturin develop --skip-install`, which
#   leaves the rebuild decision to cargo: a no-op when no Rust source changed.

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$REPO_ROOT/.venv"
PYTHON="$VENV/bin/python"
export PIP_DISABLE_PIP_VERSION_CHECK=1

# Prints a phase header.
phase() {
    printf '\n==> %s\n' "$*"
}

blendtrack_setup() {
    cd "$REPO_ROOT"

    if [[ ! -x "$PYTHON" ]]; then
        phase "setup: creating .venv (python3.11)"
        python3.11 -m venv "$VENV"
        "$PYTHON" -m pip install --quiet --upgrade pip
    fi

    local install=(-m pip install --progress-bar off --editable '.[dev]')
    local stamp="$VENV/.blendtrack-install" want
    want="$({ cat pyproject.toml; echo "${install[*]}"; } | sha256sum | cut -d' ' -f1)"
    if [[ "$(cat "$stamp" 2>/dev/null)" != "$want" ]]; then
        phase "setup: pip install -e '.[dev]' (dependencies and first build)"
        "$PYTHON" "${install[@]}"
        printf '%s\n' "$want" >"$stamp"
    fi

    phase "setup: native module (maturin develop, release)"
    VIRTUAL_ENV="$VENV" "$VENV/bin/maturin" develop --release --skip-install
}
