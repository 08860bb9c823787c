"""Issue 19 item 3: every public name resolves, and no public name is both a module and
a function or class (``jaxfric.identify`` used to be both: ``jaxfric.identify.default_solver``
raised AttributeError once the function shadowed the subpackage)."""

from __future__ import annotations

import importlib
import pkgutil
import types

import jaxfric


def _submodules(package) -> set[str]:
    return {m.name for m in pkgutil.iter_modules(package.__path__)}


def test_no_public_name_is_both_a_module_and_an_object():
    packages = [jaxfric, importlib.import_module("jaxfric.optim"),
                importlib.import_module("jaxfric.models"), importlib.import_module("jaxfric.rig")]
    for pkg in packages:
        subs = _submodules(pkg)
        for name in getattr(pkg, "__all__", ()):
            value = getattr(pkg, name)
            if not isinstance(value, types.ModuleType):
                assert name not in subs, f"{pkg.__name__}.{name} is both a submodule and a {type(value).__name__}"


def test_identify_is_the_function_and_its_package_has_its_own_name():
    from jaxfric.identification import default_solver, identify

    assert jaxfric.identify is identify
    importlib.import_module("jaxfric.identification._api")  # importing the package must not rebind the name
    assert jaxfric.identify is identify
    assert callable(default_solver)
