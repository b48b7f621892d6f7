"""The type stubs describe the extension module as built (no drift)."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import vrsync
from vrsync import _vrsync

STUB = Path(vrsync.__file__).with_name("_vrsync.pyi")


def stub_names() -> dict[str, set[str]]:
    """Top-level names of the stub, and the members each stub class declares."""
    tree = ast.parse(STUB.read_text())
    names: dict[str, set[str]] = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names[node.name] = {
                n.name if isinstance(n, ast.FunctionDef) else n.target.id  # type: ignore[union-attr]
                for n in node.body
                if isinstance(n, ast.FunctionDef)
                or (isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name))
            }
        elif isinstance(node, ast.FunctionDef):
            names[node.name] = set()
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names[node.target.id] = set()
    return names


def public(obj: object) -> set[str]:
    return {n for n in dir(obj) if not n.startswith("_")}


def test_every_public_name_of_the_module_is_in_the_stub_and_back() -> None:
    stub = stub_names()
    module = public(_vrsync) | {"__version__"}
    assert module == set(stub), (module ^ set(stub))


def test_every_public_member_of_each_class_is_in_the_stub() -> None:
    stub = stub_names()
    for name, members in stub.items():
        obj = getattr(_vrsync, name)
        if not inspect.isclass(obj):
            continue
        own = {n for n in public(obj) if n not in public(_vrsync.Command) or name == "Command"}
        assert own <= members | public(object), (name, own - members)


def test_the_package_exports_what_its_all_says() -> None:
    for name in vrsync.__all__:
        assert hasattr(vrsync, name), name
    assert set(vrsync.__all__) >= public(_vrsync) - {"FrameIter"}
