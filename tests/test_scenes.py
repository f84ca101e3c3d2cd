"""Scene loading (diffcloth_gym.scenes): shipped scenes are package data, found by name from
any working folder; the contact-free copy keeps the cloth and drops every contact effect."""

import numpy as np
import pytest

import diffcloth_gym
from diffcloth_gym import ConfigError, Simulator
from diffcloth_gym.scenes import CONFIG_DIR, CONTACT_EFFECTS, contact_free, load_scene, scene_names

SHIPPED = ["bowl", "dress", "flag", "hat", "napkin", "pyramid", "slope", "sock", "sphere", "sphere_mu", "tshirt", "wind"]


def test_shipped_scenes_are_package_data():
    assert scene_names() == SHIPPED
    assert (CONFIG_DIR / "hat.toml").is_file()
    # Inside the package, not beside it: an installed package finds them too.
    assert str(CONFIG_DIR).startswith(str(diffcloth_gym.__path__[0]))


@pytest.mark.parametrize("name", SHIPPED)
def test_load_scene_of_every_shipped_name_builds_a_simulator(name):
    cfg = load_scene(name)
    assert isinstance(cfg, dict) and cfg["effects"]
    sim = Simulator.from_config(cfg)
    assert sim.num_nodes > 0 and sim.effects == cfg["effects"]


def test_names_are_found_from_any_working_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Simulator.from_config("napkin").step()


def test_load_scene_accepts_paths_and_dicts_and_returns_fresh_copies(tmp_path):
    path = tmp_path / "my_wind.toml"
    path.write_text((CONFIG_DIR / "wind.toml").read_text())
    assert load_scene(path) == load_scene("wind") == load_scene(str(path))
    a = load_scene("wind")
    a["mesh"]["rows"] = 3
    assert load_scene("wind")["mesh"]["rows"] != 3
    d = load_scene(a)
    d["mesh"]["rows"] = 4
    assert a["mesh"]["rows"] == 3


def test_mesh_overrides():
    cfg = load_scene("wind", rows=6, cols=7)
    assert (cfg["mesh"]["rows"], cfg["mesh"]["cols"]) == (6, 7)
    assert Simulator.from_config(cfg).num_nodes == 42


def test_unknown_name_raises_config_error_naming_the_shipped_scenes():
    with pytest.raises(ConfigError) as err:
        load_scene("no_such_scene")
    assert "no_such_scene" in str(err.value)
    for name in SHIPPED:
        assert name in str(err.value)
    with pytest.raises(ConfigError, match="sock"):
        Simulator.from_config("no_such_scene")


def test_malformed_toml_raises_config_error(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("h = = 1\n")
    with pytest.raises(ConfigError, match="broken.toml"):
        load_scene(path)


@pytest.mark.parametrize("name", ["hat", "sock", "sphere", "bowl", "slope"])
def test_contact_free_has_no_contact_effect_and_steps(name):
    full = load_scene(name)
    free = contact_free(full)
    assert not set(free["effects"]) & set(CONTACT_EFFECTS)
    assert "obstacles" not in free and "self_collision" not in free and "contact" not in free
    # Everything else is the scene's, and the original is untouched.
    assert free["mesh"] == full["mesh"] and free.get("material") == full.get("material")
    assert full == load_scene(name)
    sim = Simulator.from_config(free)
    stats = sim.step(steps=3)
    assert stats["contacts"] == {"take_off": 0, "stick": 0, "slip": 0}
    assert sim.contacts()["branch"].size == 0
    assert np.isfinite(sim.positions).all()
    assert not set(sim.effects) & set(CONTACT_EFFECTS)
