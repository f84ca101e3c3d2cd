"""The README's layout table matches the tracked tree (``git ls-files``): every path it names
exists, and every top-level entry and every folder directly under ``diffcloth_gym/`` and
``rust/`` is in it. Folder-level on purpose: files inside ``rust/*/src`` may move freely."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Backticked words in the "what" column that are checked as paths (relative to the row's folder).
PATH_SUFFIXES = (".py", ".rs", ".toml", ".md", ".sh", "/")


def tracked() -> list[str]:
    if shutil.which("git") is None:
        pytest.skip("git is not available")
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip(f"not a git checkout: {out.stderr.strip()}")
    return out.stdout.splitlines()


def layout_rows() -> list[tuple[list[str], list[str]]]:
    """``(paths of the first column, backticked words of the second)`` per table row."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 2 or cells[0] in ("path", "---"):
            continue
        rows.append((re.findall(r"`([^`]+)`", cells[0]), re.findall(r"`([^`]+)`", cells[1])))
    return rows


def exists(path: str, files: list[str]) -> bool:
    if path.endswith("/"):
        return any(f.startswith(path) for f in files)
    return path in files


def test_every_path_in_the_layout_table_is_tracked():
    files = tracked()
    rows = layout_rows()
    assert rows, "README.md has no layout table"
    missing = []
    for paths, words in rows:
        missing += [p for p in paths if not exists(p, files)]
        folder = next((p for p in paths if p.endswith("/")), None)
        if folder is None:
            continue
        for w in words:
            if " " not in w and w.endswith(PATH_SUFFIXES) and not exists(folder + w, files):
                missing.append(folder + w)
    assert not missing, f"README layout names untracked paths: {missing}"


def test_the_layout_table_lists_every_top_level_entry_and_package_folder():
    files = tracked()
    listed = {p.rstrip("/") for paths, _ in layout_rows() for p in paths}
    expected = {f.split("/")[0] for f in files}
    for parent in ("diffcloth_gym", "rust"):
        expected |= {"/".join(f.split("/")[:2]) for f in files if f.startswith(parent + "/") and f.count("/") >= 2}
    missing = sorted(expected - listed)
    assert not missing, f"README layout table does not list: {missing}"
