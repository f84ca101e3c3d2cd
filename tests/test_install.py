"""The package as a user installs it: a wheel, unpacked outside the checkout, finds its scene
configs (package data) and steps a shipped scene from any folder."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MATURIN = Path(sys.executable).parent / "maturin"


def run(args, **kwargs):
    out = subprocess.run(args, capture_output=True, text=True, **kwargs)
    assert out.returncode == 0, f"{args[:3]} failed:\n{out.stdout}\n{out.stderr}"
    return out


@pytest.mark.skipif(not MATURIN.exists(), reason="maturin is installed by scripts/_setup.sh")
def test_an_installed_wheel_finds_its_scenes(tmp_path):
    wheels = tmp_path / "wheels"
    # Same profile as scripts/_setup.sh's develop build: the release target is reused.
    run([str(MATURIN), "build", "--release", "--quiet", "-o", str(wheels)], cwd=ROOT)
    (wheel,) = wheels.glob("*.whl")
    site = tmp_path / "site"
    run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
         "--disable-pip-version-check", "--target", str(site), str(wheel)])
    assert not (site / "benchmarks").exists(), "benchmark code must not ship in the wheel"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    script = (
        "import diffcloth_gym, sys\n"
        f"assert diffcloth_gym.__file__.startswith({str(site)!r}), diffcloth_gym.__file__\n"
        "from diffcloth_gym import Simulator, scene_names\n"
        "assert 'hat' in scene_names(), scene_names()\n"
        "s = Simulator.from_config('hat')\n"
        "s.step()\n"
        # Package data beyond TOMLs: the task scenes' procedural OBJ meshes.
        "Simulator.from_config('dress').step()\n"
        "Simulator.from_config('tshirt').step()\n"
        "print(s.num_nodes)\n"
    )
    # The wheel's copy comes first on the path; the checkout is not on it (cwd elsewhere).
    out = run([sys.executable, "-c", script], cwd=elsewhere,
              env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"})
    assert int(out.stdout.strip()) > 0
    shutil.rmtree(wheels)
