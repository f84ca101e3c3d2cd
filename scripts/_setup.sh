# Shared set-up for scripts/demo and scripts/test (sourced): a project-local venv with the
# Python dependencies, and the Rust extension built in release mode. Idempotent and
# incremental: a second run only rebuilds what changed.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
command -v cargo >/dev/null || { echo "error: cargo (Rust) is required: https://rustup.rs" >&2; exit 1; }
if [ ! -x "$PY" ]; then
  echo "== creating $VENV"
  python3 -m venv "$VENV"
fi
# Install Python dependencies when pyproject.toml changed since the last install.
STAMP="$VENV/.deps-$(sha1sum pyproject.toml | cut -c1-16)"
if [ ! -f "$STAMP" ]; then
  echo "== installing Python dependencies"
  # torch: the CPU runs use PyPI's default wheel (it brings CUDA libraries; ~1-2 min fresh).
  "$PY" -m pip install -q --disable-pip-version-check "maturin>=1.9.4,<2" "numpy>=1.26" "pytest>=8" \
    "matplotlib>=3.8" "torch>=2.8" "gymnasium>=1.4" "stable-baselines3>=2.9" "moviepy>=2" \
    "tqdm>=4.66" "pillow>=10" "hypothesis>=6" "tensorboard>=2.16" \
    "scipy>=1.11" "cma>=3.3"
  rm -f "$VENV"/.deps-*
  touch "$STAMP"
fi
echo "== building the Rust extension (release)"
# A stale per-version extension would shadow the abi3 one.
find "$ROOT/diffcloth_gym" -maxdepth 1 -name '_core.cpython-*.so' -delete
# As a module: a copied venv's console scripts point at the interpreter they were made with.
"$PY" -m maturin develop --release --quiet
"$PY" -c "import diffcloth_gym" || { echo "error: the extension did not build" >&2; exit 1; }
