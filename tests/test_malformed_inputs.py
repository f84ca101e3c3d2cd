"""Issue 11 item 6 (the rest): malformed files, paths and placements raised Python's own
errors (RecursionError, UnicodeDecodeError), InternalError, a solver error that named nothing,
or silently did something odd. Each is now a ``diffcloth_gym.errors`` exception naming it."""

import pytest

import diffcloth_gym
from diffcloth_gym import Simulator, load_scene

from .conftest import SMALL_GRID

SQUARE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"

def obj_config(tmp_path, name, data: bytes) -> dict:
    path = tmp_path / name
    path.write_bytes(data)
    return {**SMALL_GRID, "mesh": {"kind": "obj", "path": str(path)}, "attachments": {"nodes": [0]}}

def test_deeply_nested_toml_is_a_config_error(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000)
    with pytest.raises(diffcloth_gym.ConfigError, match="deep.toml: .*nested too deeply"):
        Simulator.from_config(path)

def test_deeply_nested_dict_config_is_a_config_error():
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    with pytest.raises(diffcloth_gym.ConfigError, match="nested too deeply"):
        Simulator.from_config({**SMALL_GRID, "name": deep})

def test_toml_that_is_not_utf8_is_a_config_error_naming_the_byte(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(diffcloth_gym.ConfigError, match=r"latin1.toml: not UTF-8 text \(byte 11"):
        Simulator.from_config(path)

def test_toml_with_a_byte_order_mark_loads(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + (diffcloth_gym.scenes.CONFIG_DIR / "napkin.toml").read_bytes())
    assert Simulator.from_config(path).num_nodes == Simulator.from_config("napkin").num_nodes

@pytest.mark.parametrize("path", [None, 3, b"out.obj", ""])
def test_write_obj_needs_a_path(small, tmp_path, monkeypatch, path):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(diffcloth_gym.InputError, match="path must be a file path"):
        small.write_obj(path)
    assert list(tmp_path.iterdir()) == []  # before: a file named "None"

@pytest.mark.parametrize("placement, named", [
    ({"scale": 1e150}, "scale = 1e150"),
    ({"scale": 1e-150}, "scale = 1e-150"),
    ({"translate": [1e300, 0, 0]}, "translate = [1e300"),
])
def test_a_placement_that_ruins_the_mesh_is_a_config_error(placement, named):
    cfg = load_scene("napkin")
    cfg["placement"] = {**cfg["placement"], **placement}
    # Before: InternalError (a panic) for the large scale, SolverError for the others.
    with pytest.raises(diffcloth_gym.ConfigError, match="placement") as e:
        Simulator.from_config(cfg)
    assert named in str(e.value)

def test_obj_with_an_unused_vertex_names_it(tmp_path):
    cfg = obj_config(tmp_path, "unused.obj", (SQUARE + "v 5 5 5\n").encode())
    # Before: "system matrix is not positive definite" (the vertex has no mass).
    with pytest.raises(diffcloth_gym.MeshError, match="unused.obj: line 7: vertex 5 is used by no face"):
        Simulator.from_config(cfg)

def test_obj_with_a_byte_order_mark_keeps_its_first_vertex(tmp_path):
    # Before: the BOM hid the first "v" record, and face 4 was then out of range.
    sim = Simulator.from_config(obj_config(tmp_path, "bom.obj", b"\xef\xbb\xbf" + SQUARE.encode()))
    assert sim.num_nodes == 4
    assert sim.rest_positions[0].tolist() == [0.0, 0.0, 0.0]
