import pytest

from diffcloth_gym import Simulator


@pytest.fixture
def wind():
    return Simulator.from_config("wind")


SMALL_GRID = {
    "h": 0.01,
    "effects": ["gravity", "stretch", "attachments", "external_forces"],
    "mesh": {"kind": "grid", "rows": 5, "cols": 5, "width": 1.0, "height": 1.0, "plane": "xy"},
    "material": {"density": 0.1, "k_stretch": 100.0},
    "attachments": {"select": "top_corners"},
}


@pytest.fixture
def small():
    return Simulator.from_config(SMALL_GRID)


def pytest_addoption(parser):
    parser.addoption("--full", action="store_true", default=False,
                     help="run tests/stability at the full (issue) sizes instead of the CI sizes (minutes), "
                          "and ten times the property-based examples (tests/test_properties.py)")


#: Set from --full before the test modules are imported (they size themselves by it).
FULL = False


def pytest_configure(config):
    global FULL
    FULL = config.getoption("--full")
    config.addinivalue_line(
        "markers", "stability: hard-case numerical stability suite (tests/stability; --full for the full sizes)")
