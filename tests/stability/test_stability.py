"""The hard-case stability suite (``benchmarks/stability/``) as tests.

Every case runs once per session, at the CI size or, with ``pytest --full``, at the full size.
``test_case`` asserts all of a case's checks (finite states and gradients, no node inside an
obstacle or deep in the thickness layer, self pairs apart, energy bound, backward without
errors, the case's physical facts) except those listed in ``KNOWN_ISSUES``: simulator bugs the
suite reveals, each asserted by ``test_known_issue`` as a strict expected failure (a fix makes it
pass unexpectedly, which fails until the entry is removed). Backward fallbacks and gradient
warnings are reported (``record_property``, and printed), not asserted.
"""

from __future__ import annotations

import pytest

from benchmarks import stability as st

pytestmark = pytest.mark.stability

_RESULTS: dict[tuple[str, str], dict | BaseException] = {}


def _size(config: pytest.Config) -> str:
    return "full" if config.getoption("--full") else "ci"


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    size = _size(metafunc.config)
    if metafunc.definition.name == "test_known_issue":
        params = [pytest.param(case, check, id=f"{case}-{check}",
                               marks=pytest.mark.xfail(strict=True, reason="; ".join(
                                   f"{issue}: {st.ISSUES[issue][0]}" for issue in issues.split(", "))))
                  for (case, check) in st.KNOWN_ISSUES
                  if (issues := st.known_issue(case, check, size))]
        metafunc.parametrize("case, check", params)
    elif "case" in metafunc.fixturenames:
        metafunc.parametrize("case", list(st.CASES))


@pytest.fixture(scope="session")
def size(request: pytest.FixtureRequest) -> str:
    return _size(request.config)


def result(case: str, size: str, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The case's result, computed on first use. An exception (a panic surfaces as
    ``InternalError``) propagates from the first test of the case and fails the others too."""
    key = (case, size)
    if key not in _RESULTS:
        try:
            _RESULTS[key] = st.run_case(case, size, tmp_path_factory.mktemp(case))
        except Exception as e:
            _RESULTS[key] = e
            raise
    r = _RESULTS[key]
    if isinstance(r, BaseException):
        raise RuntimeError(f"case {case} raised {r!r} (traceback in its first test)") from r
    return r


def test_case(case: str, size: str, tmp_path_factory: pytest.TempPathFactory,
              record_property: pytest.RecordProperty) -> None:
    r = result(case, size, tmp_path_factory)
    for key in ("steps", "max_penetration_m", "max_layer_intrusion_m", "min_self_distance_m", "max_energy_ratio",
                "backward_steps", "fallbacks", "grad_warnings", "unconverged_steps", "nan_count", "wall_s"):
        record_property(key, r[key])
    print(f"{case} ({size}): {r['steps']} steps, penetration {r['max_penetration_m']}, layer {r['max_layer_intrusion_m']}, "
          f"self {r['min_self_distance_m']}, energy ratio {r['max_energy_ratio']}, fallbacks {r['fallbacks']}/"
          f"{r['backward_steps']}, gradient warnings {r['grad_warnings']}, unconverged steps {r['unconverged_steps']}")
    checks = st.evaluate(r)
    assert checks, "a case must check something"
    failed = {k: msg for k, (ok, msg) in checks.items() if not ok and not st.known_issue(case, k, size)}
    report = "\n".join(f"  {k}: {msg}" for k, msg in failed.items())
    assert not failed, (f"{case} ({size}) fails {sorted(failed)} "
                        f"(backward fallbacks: {r['fallbacks']} of {r['backward_steps']} steps):\n{report}")


def test_known_issue(case: str, check: str, size: str, tmp_path_factory: pytest.TempPathFactory) -> None:
    """A simulator bug listed in ``KNOWN_ISSUES``: the check must hold once it is fixed."""
    ok, msg = st.evaluate(result(case, size, tmp_path_factory))[check]
    assert ok, msg


def test_known_issues_name_existing_cases_and_checks() -> None:
    checks = {"finite", "penetration", "thickness_layer", "self_distance", "energy", "backward", "physics"}
    for (case, check), (sizes, issues) in st.KNOWN_ISSUES.items():
        assert case in st.CASES and check in checks and set(sizes) <= set(st.SIZES), (case, check)
        assert issues and set(issues) <= set(st.ISSUES), (case, check, issues)
