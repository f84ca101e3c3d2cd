"""Writing benchmark results: JSON with a meta block plus a Markdown table of the same rows."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

#: Where the committed results live: ``benchmarks/results/`` beside this package.
RESULTS_DIR = Path(__file__).resolve().parent / "results"


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git() -> str:
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def meta(extra: dict | None = None) -> dict:
    m = {
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "threads": os.cpu_count(),
        "cpu": _cpu(),
        "git": _git(),
    }
    m.update(extra or {})
    return m


def _fmt(v) -> str:
    if isinstance(v, float):
        if v == 0:
            return "0"
        if abs(v) >= 1000 or abs(v) < 1e-2:
            return f"{v:.2e}"
        return f"{v:.3g}"
    return str(v)


def markdown_table(rows: list[dict], columns: list[str] | None = None) -> str:
    columns = columns or list(dict.fromkeys(k for r in rows for k in r))
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c, "")) for c in columns) + " |")
    return "\n".join(lines)


def write(name: str, rows: list[dict], meta_block: dict, title: str, notes: str = "", columns: list[str] | None = None, out_dir: Path | None = None,
          extra: dict | None = None) -> Path:
    """``name.json`` (``meta``, ``rows`` and the entries of ``extra``) and ``name.md``."""
    out = Path(out_dir or RESULTS_DIR)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"meta": meta_block, "rows": rows, **(extra or {})}
    (out / f"{name}.json").write_text(json.dumps(doc, indent=1) + "\n")
    md = [f"# {title}", "", f"`{meta_block['command']}` — {meta_block['date']}, {meta_block['cpu']}, git {meta_block['git']}", ""]
    if notes:
        md += [notes.strip(), ""]
    md.append(markdown_table(rows, columns))
    (out / f"{name}.md").write_text("\n".join(md) + "\n")
    return out / f"{name}.json"


def write_merged(name: str, rows: list[dict], key, meta_block: dict, title: str, notes: str = "",
                 out_dir: Path | None = None) -> Path:
    """``write`` that keeps the earlier rows whose ``key(row)`` none of ``rows`` has (for
    studies whose runs measure part of the table, and write after every measurement).

    Each run's meta block is kept as long as it has rows: the JSON's ``runs`` maps a run id
    (``r1``, ``r2``, ...) to its meta, every row names its run in ``run``, and the Markdown
    lists the runs (command, date, machine, git and the run's ``note``) above the table, so
    a rerun of one part does not erase where the other rows came from. Rows written before
    runs were recorded keep the file's last meta as theirs, the best that is known."""
    path = Path(out_dir or RESULTS_DIR) / f"{name}.json"
    old_doc = json.loads(path.read_text()) if path.exists() else {}
    done = {key(r) for r in rows}
    runs = dict(old_doc.get("runs", {}))
    old = [dict(r) for r in old_doc.get("rows", []) if key(r) not in done]
    if any("run" not in r for r in old):
        runs.setdefault("r0", old_doc["meta"])
        for r in old:
            r.setdefault("run", "r0")
    this = next((rid for rid, m in runs.items() if m == meta_block), None)
    if this is None:
        this = f"r{1 + max((int(rid[1:]) for rid in runs), default=0)}"
        runs[this] = meta_block
    merged = old + [{**r, "run": this} for r in rows]
    used = {r["run"] for r in merged}
    runs = {rid: m for rid, m in sorted(runs.items(), key=lambda kv: int(kv[0][1:])) if rid in used}
    listing = ["Runs (the `run` column):", ""] + [
        f"- {rid}: `{m['command']}` — {m['date']}, {m.get('cpu', '?')}, git {m.get('git', '?')}"
        + (f". {m['note']}" if m.get("note") else "")
        for rid, m in runs.items()
    ]
    return write(name, merged, meta_block, title, "\n".join(listing) + ("\n\n" + notes.strip() if notes else ""),
                 out_dir=out_dir, extra={"runs": runs})
