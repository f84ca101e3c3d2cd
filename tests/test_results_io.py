"""Merged benchmark results (``results_io.write_merged``) keep where every row came from: a
rerun of part of a table replaces its own rows and leaves the other rows' runs (command, date,
git, note) in the JSON and the Markdown."""

import json

from benchmarks import results_io


def run(note: str, date: str) -> dict:
    return {"command": f"bench --note {note}", "date": date, "cpu": "cpu", "git": "abc", "note": note}


def key(row: dict):
    return (row["label"], row["scene"])


def written(tmp_path):
    doc = json.loads((tmp_path / "t.json").read_text())
    return doc, (tmp_path / "t.md").read_text()


def test_a_partial_rerun_keeps_the_other_rows_and_their_run(tmp_path):
    first, second = run("first build", "2026-01-01"), run("second build", "2026-01-02")
    rows = [{"label": "a", "scene": s, "ms": 1.0} for s in ("hat", "sock")]
    results_io.write_merged("t", rows, key, first, "T", "about T", out_dir=tmp_path)
    results_io.write_merged("t", [{"label": "a", "scene": "hat", "ms": 2.0}], key, second, "T", "about T",
                            out_dir=tmp_path)
    doc, md = written(tmp_path)
    by_scene = {r["scene"]: r for r in doc["rows"]}
    assert by_scene["hat"]["ms"] == 2.0 and by_scene["sock"]["ms"] == 1.0
    assert doc["runs"][by_scene["sock"]["run"]] == first
    assert doc["runs"][by_scene["hat"]["run"]] == second
    assert "first build" in md and "second build" in md and "about T" in md
    assert doc["meta"] == second


def test_calls_of_one_run_share_its_id_and_a_run_without_rows_is_dropped(tmp_path):
    first, second = run("first", "2026-01-01"), run("second", "2026-01-02")
    results_io.write_merged("t", [{"label": "a", "scene": "hat"}], key, first, "T", out_dir=tmp_path)
    # One run writing after each measurement (as gradient_cost does): the same run id.
    rows = [{"label": "a", "scene": "hat"}]
    results_io.write_merged("t", rows, key, second, "T", out_dir=tmp_path)
    rows.append({"label": "a", "scene": "sock"})
    results_io.write_merged("t", rows, key, second, "T", out_dir=tmp_path)
    doc, md = written(tmp_path)
    assert list(doc["runs"].values()) == [second]
    assert {r["run"] for r in doc["rows"]} == set(doc["runs"])
    assert "first" not in md.split("|", 1)[0]


def test_rows_from_before_runs_were_recorded_keep_the_files_meta(tmp_path):
    legacy = run("legacy", "2025-12-31")
    results_io.write("t", [{"label": "old", "scene": "hat"}], legacy, "T", out_dir=tmp_path)
    results_io.write_merged("t", [{"label": "new", "scene": "hat"}], key, run("new", "2026-01-01"), "T",
                            out_dir=tmp_path)
    doc, _ = written(tmp_path)
    old = next(r for r in doc["rows"] if r["label"] == "old")
    assert doc["runs"][old["run"]] == legacy
