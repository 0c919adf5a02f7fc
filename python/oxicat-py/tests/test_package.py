"""The package as installed: its pytest plugin is registered and its type stubs describe
the native module as it is."""

import ast
import importlib.metadata
import pathlib

import oxicat


def test_the_pytest_plugin_is_registered(pytestconfig):
    eps = importlib.metadata.entry_points()
    group = eps.select(group="pytest11") if hasattr(eps, "select") else eps.get("pytest11", [])
    assert any(ep.value == "oxicat.pytest_plugin" for ep in group), list(group)
    assert pytestconfig.pluginmanager.has_plugin("oxicat")


def test_the_type_stubs_name_every_public_member_of_the_native_module():
    pkg = pathlib.Path(oxicat.__file__).parent
    assert (pkg / "py.typed").is_file()
    tree = ast.parse((pkg / "_oxicat.pyi").read_text())
    stub = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            stub[node.name] = {
                n.name for n in node.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            }
        elif isinstance(node, ast.FunctionDef):
            stub[node.name] = set()
    native = oxicat._oxicat
    public = {n for n in dir(native) if not n.startswith("_")}
    assert public == set(stub), (public, set(stub))
    members = {n for n in dir(native.Segment) if not n.startswith("_")}
    members |= {"__len__", "__enter__", "__exit__", "__init__"}
    assert members == stub["Segment"], (members ^ stub["Segment"])
