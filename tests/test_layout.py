"""The README's layout table matches the tracked tree (``git ls-files``; outside a git checkout,
the files on disk that ``.gitignore`` does not exclude): every path it names exists, and every
top-level entry and every folder directly under ``diffcloth_gym/`` and ``rust/`` is in it.
Folder-level on purpose: files inside ``rust/*/src`` may move freely."""

import fnmatch
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Backticked words in the "what" column that are checked as paths (relative to the row's folder).
PATH_SUFFIXES = (".py", ".rs", ".toml", ".md", ".sh", "/")


def git_files() -> list[str] | None:
    """``git ls-files``, or None without git or outside a checkout (a source archive)."""
    if shutil.which("git") is None:
        return None
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    return out.stdout.splitlines() if out.returncode == 0 else None


def tracked() -> list[str]:
    """The tracked files, or :func:`on_disk` where git cannot say: the layout holds either way."""
    files = git_files()
    return on_disk() if files is None else files


def on_disk() -> list[str]:
    """The files under the root that ``.gitignore``'s patterns (this repository uses only
    names, globs and root-anchored folders) and ``.git`` leave."""
    patterns = [p.strip() for p in (ROOT / ".gitignore").read_text().splitlines()
                if p.strip() and not p.startswith("#")]

    def ignored(rel: Path) -> bool:
        for pattern in patterns:
            name = pattern.strip("/")
            if pattern.startswith("/"):
                if rel.parts[0] == name:
                    return True
            elif any(fnmatch.fnmatch(part, name) for part in rel.parts):
                return True
        return rel.parts[0] == ".git"

    files = (p.relative_to(ROOT) for p in ROOT.rglob("*") if p.is_file())
    return sorted(rel.as_posix() for rel in files if not ignored(rel))


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


def test_the_listing_without_git_finds_every_tracked_file_and_nothing_ignored():
    files = git_files()
    if files is None:
        pytest.skip("no git checkout to compare with (the tests above already list the files on disk)")
    disk = set(on_disk())
    git = [f for f in files if (ROOT / f).is_file()]  # (a deletion not yet committed)
    assert not [f for f in git if f not in disk], "on_disk() misses tracked files"
    assert not [f for f in disk if f.startswith((".venv/", "target/", ".git/")) or f.endswith(".pyc")]
