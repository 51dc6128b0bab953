#!/usr/bin/env bash
# Set up what the tests need on a fresh Debian or Ubuntu machine, then run every test: Rust
# (cargo test), then the Python package (built with maturin into a virtual environment, tested
# with pytest, Mitsuba 3 for the plugin's tests), then Blender's Cycles (the bpy module in its own
# virtual environment, .venv-blender/), then the browser tests (three.js,
# <model-viewer> and `fibrefit view`'s page in headless Chromium, tests/browser). Safe to run
# again: it installs only what is missing, and the virtual environment (.venv-test/) is kept
# between runs.
set -euo pipefail
cd "$(dirname "$0")/.."
# where the time goes: each phase's wall seconds on stderr, and a summary at the end
phases=()
phase_start=$SECONDS
phase() { phases+=("$1 $((SECONDS - phase_start)) s"); echo "scripts/test.sh: $1 took $((SECONDS - phase_start)) s" >&2; phase_start=$SECONDS; }
trap 'echo "scripts/test.sh: phases: ${phases[*]:-none}; total $SECONDS s" >&2' EXIT

# apt: the shader tests run the exported shader on a GPU driver (the CPU Vulkan driver
# llvmpipe, mesa-vulkan-drivers); the exported GLSL is compiled by glslang (glslang-tools); the
# Python tests render with Mitsuba 3's LLVM variant, which needs libLLVM 16 or newer (Debian 12's
# default is 15: libllvm19); the Python package needs venv and pip
need=()
compgen -G "/usr/share/vulkan/icd.d/lvp_icd*.json" >/dev/null || need+=(mesa-vulkan-drivers)
command -v glslangValidator >/dev/null || need+=(glslang-tools)
compgen -G "/usr/lib/*/libLLVM-19.so*" >/dev/null || compgen -G "/usr/lib/*/libLLVM.so.19*" >/dev/null || need+=(libllvm19)
python3 -c "import venv, ensurepip" 2>/dev/null || need+=(python3-venv)
# the calibration board's markers (fibrefit board, calibrate): the AprilTag library, linked
# through pkg-config
pkg-config --exists apriltag 2>/dev/null || need+=(libapriltag-dev pkg-config)
# the browser tests (tests/browser): three.js and <model-viewer> in headless Chromium, driven by
# node (playwright-core from npm)
command -v chromium >/dev/null || need+=(chromium)
command -v npm >/dev/null || need+=(npm)
command -v cargo >/dev/null || { echo "scripts/test.sh: cargo not found: install Rust first (https://rustup.rs)" >&2; exit 2; }
if [ ${#need[@]} -gt 0 ]; then
    echo "scripts/test.sh: installing ${need[*]}" >&2
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get install -y --no-install-recommends "${need[@]}" ||
        { $sudo apt-get update -q && $sudo apt-get install -y --no-install-recommends "${need[@]}"; }
fi

# pip: the Python package's build and test tools, in a virtual environment that sees the
# system's packages (nothing already installed is downloaded again)
venv=.venv-test
[ -x "$venv/bin/python" ] || python3 -m venv --system-site-packages "$venv"
py="$venv/bin/python"
# MaterialX (validates the --materialx document, generates its GLSL for the compile check and
# the WebGL renders of tests/browser/materialx.mjs) and usd-core (opens and validates --usd)
"$py" -m pip install --quiet --disable-pip-version-check "numpy>=1.21" "pandas>=1.3" pytest "maturin>=1.5,<2" "mitsuba>=3.5" \
    "materialx==1.39.5" "usd-core==26.11"
# Blender's Python module for the Blender tests (python/tests/test_blender.py: the `principled`
# rung rendered by Cycles): bpy 5.0.1 (374 MB, once) needs Python 3.11 and numpy < 2, so it has
# its own virtual environment, kept between runs like the other
bvenv=.venv-blender
[ -x "$bvenv/bin/python" ] || python3 -m venv "$bvenv"
bpy_py="$bvenv/bin/python"
"$bpy_py" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' ||
    { echo "scripts/test.sh: Blender's bpy 5.0.1 needs Python 3.11 ($bvenv has $("$bpy_py" --version))" >&2; exit 2; }
"$bpy_py" -m pip install --quiet --disable-pip-version-check "bpy==5.0.1" "numpy>=1.26,<2" pytest
phase "set-up (apt, pip)"

# every test; a fresh build gains nothing from incremental compilation (it only costs time and
# disk), so it is off unless the caller says otherwise
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
# the benches too (built, not run: `cargo bench` measures): a bench that no longer compiles
# is a speed figure nobody can reproduce
cargo test --no-run --all-targets
phase "building the Rust tests"
cargo test --no-fail-fast
phase "running the Rust tests"
# one wheel, installed into both environments
rm -rf target/python-wheel
"$py" -m pip wheel --quiet --disable-pip-version-check --no-deps ./python -w target/python-wheel
"$py" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/python-wheel/fibrefit-*.whl
"$bpy_py" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/python-wheel/fibrefit-*.whl
phase "building the Python package"
FIBREFIT_REQUIRE_MATERIALX=1 "$py" -m pytest -q python/tests --ignore=python/tests/test_blender.py
phase "running the Python tests"
FIBREFIT_REQUIRE_BPY=1 "$bpy_py" -m pytest -q python/tests/test_blender.py
phase "running the Blender tests (Cycles)"

# the browser tests: the exported GLB in three.js and <model-viewer> (tests/browser/run.mjs). The
# npm packages (pinned by package-lock.json) go into tests/browser/node_modules, not committed,
# installed again only when the lock file changed since the last install
lock=tests/browser/package-lock.json
stamp=tests/browser/node_modules/.fibrefit-lock.sha256
if [ ! -f "$stamp" ] || [ "$(sha256sum "$lock" | cut -d' ' -f1)" != "$(cat "$stamp")" ]; then
    (cd tests/browser && npm ci --no-audit --no-fund --loglevel=error)
    sha256sum "$lock" | cut -d' ' -f1 >"$stamp"
fi
phase "installing the browser tests' npm packages"
# the fibrefit binary `cargo test` built for the Rust tests
FIBREFIT="${CARGO_TARGET_DIR:-target}/debug/fibrefit" node tests/browser/run.mjs
FIBREFIT="${CARGO_TARGET_DIR:-target}/debug/fibrefit" node tests/browser/view.mjs
# the openpbr rung in MaterialX's own generated shader (WebGL2), against the rung
FIBREFIT="${CARGO_TARGET_DIR:-target}/debug/fibrefit" PYTHON="$py" node tests/browser/materialx.mjs
phase "running the browser tests (three.js, model-viewer, fibrefit view, MaterialX)"
