"""The type stub diffcloth_gym/_core.pyi matches the compiled extension, so it cannot drift."""

import ast
import inspect
import types
from pathlib import Path

import pytest

import diffcloth_gym
from diffcloth_gym import _core

# Next to the compiled module, where type checkers look and where the wheel must ship it.
STUB = Path(_core.__file__).with_name("_core.pyi")


def _stub_class(name: str) -> ast.ClassDef:
    tree = ast.parse(STUB.read_text())
    return next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name)


#: The extension's classes whose members are checked against the stub.
CLASSES = ("Simulator", "Batch", "Renderer")


def _stub_members(cls: str = "Simulator") -> dict[str, ast.FunctionDef]:
    """Public members of a stubbed class; a property's setter shares its getter's name."""
    members = {}
    for node in _stub_class(cls).body:
        if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
            members.setdefault(node.name, node)
    return members


def _decorators(fn: ast.FunctionDef) -> set[str]:
    return {ast.unparse(d) for d in fn.decorator_list}


def _stub_params(fn: ast.FunctionDef) -> list[tuple[str, object]]:
    """(name, default) of each parameter after self; "**name" for a keyword catch-all."""
    args = fn.args
    plain = args.posonlyargs + args.args
    if "staticmethod" not in _decorators(fn):
        plain = plain[1:]
    defaults = [inspect.Parameter.empty] * (len(plain) - len(args.defaults))
    defaults += [ast.literal_eval(d) for d in args.defaults]
    params = [(a.arg, d) for a, d in zip(plain, defaults)]
    if args.kwarg is not None:
        params.append(("**" + args.kwarg.arg, inspect.Parameter.empty))
    return params


def _runtime_params(obj) -> list[tuple[str, object]] | None:
    """The same from pyo3's __text_signature__, or None where pyo3 provides none."""
    if getattr(obj, "__text_signature__", None) is None:
        return None
    out = []
    for p in inspect.signature(obj).parameters.values():
        if p.name == "self":
            continue
        name = "**" + p.name if p.kind is p.VAR_KEYWORD else p.name
        out.append((name, p.default))
    return out


@pytest.mark.parametrize("cls", CLASSES)
def test_stub_names_equal_the_runtime_names(cls):
    runtime = {n for n in dir(getattr(_core, cls)) if not n.startswith("_")}
    assert set(_stub_members(cls)) == runtime


def test_module_level_names_are_stubbed():
    tree = ast.parse(STUB.read_text())
    stubbed = {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    stubbed |= {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
    runtime = {n for n in vars(_core) if not n.startswith("_") or n == "__version__"}
    assert stubbed == runtime


@pytest.mark.parametrize("cls, name", [(c, n) for c in CLASSES for n in sorted(_stub_members(c))])
def test_stubbed_member_matches_the_runtime_kind_and_signature(cls, name):
    fn = _stub_members(cls)[name]
    static = inspect.getattr_static(getattr(_core, cls), name)
    is_property = "property" in _decorators(fn)
    assert is_property == isinstance(static, types.GetSetDescriptorType)
    assert ("staticmethod" in _decorators(fn)) == isinstance(static, staticmethod)
    assert ast.get_docstring(fn), f"{name} needs a one-line docstring in the stub"
    if is_property:
        return
    runtime = _runtime_params(getattr(getattr(_core, cls), name))
    if runtime is not None:
        assert _stub_params(fn) == runtime


def test_settable_properties_are_the_stubbed_setters():
    setters = {n.name for n in _stub_class("Simulator").body
               if isinstance(n, ast.FunctionDef) and any(ast.unparse(d).endswith(".setter")
                                                          for d in n.decorator_list)}
    sim = diffcloth_gym.Simulator.from_config(
        {"h": 0.01, "effects": [], "material": {"density": 1.0},
         "mesh": {"kind": "grid", "rows": 2, "cols": 2, "width": 1.0, "height": 1.0, "plane": "xy"}})._core
    settable = set()
    for name, fn in _stub_members().items():
        if "property" in _decorators(fn):
            try:
                setattr(sim, name, getattr(sim, name))
                settable.add(name)
            except AttributeError:
                pass
    assert settable == setters


@pytest.mark.parametrize("cls", ("Batch", "Renderer"))
def test_constructor_signatures_match_the_runtime(cls):
    init = next(n for n in _stub_class(cls).body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    assert _stub_params(init) == _runtime_params(getattr(_core, cls))
