"""The full Hat comparison's pinned build (``scripts/hat_full_run``): the pin names a commit of
this history, so any checkout can build it, and one that carries the wrapper's support
(``compare_hat.py --via``). That the pinned build resumes the committed runs (their dynamics
hashes) needs the build itself: the session that pins a commit checks it, and every
``scripts/hat_full_run`` re-checks it before training."""

import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PIN = ROOT / "benchmarks" / "results" / "hat_controller_runs" / "build.toml"


def git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)


def test_the_pin_is_a_commit_of_this_history_with_the_wrappers_support():
    commit = tomllib.loads(PIN.read_text())["commit"]
    assert re.fullmatch(r"[0-9a-f]{40}", commit), commit
    # The wrapper reads the pin with sed: the same line, the same commit.
    line = next(l for l in PIN.read_text().splitlines() if l.startswith("commit"))
    assert line == f'commit = "{commit}"'
    if shutil.which("git") is None or git("rev-parse", "--git-dir").returncode != 0:
        pytest.skip("not a git checkout: the pin cannot be resolved here")
    if git("rev-parse", "--is-shallow-repository").stdout.strip() == "true":
        pytest.skip("a shallow clone may not hold the pinned commit")
    assert git("merge-base", "--is-ancestor", commit, "HEAD").returncode == 0, f"{commit} is not an ancestor of HEAD"
    wrapper = git("show", f"{commit}:scripts/compare_hat.py")
    assert wrapper.returncode == 0 and "--via" in wrapper.stdout
