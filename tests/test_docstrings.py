"""The public API's docstrings parse as numpydoc: types in the type slot, parameters that exist, no warning.

numpydoc reads an entry as ``name : type`` on one line and its description on the indented lines below.
The older layout of this code base, ``name : type -- description``, parses without error but puts the
whole first line of the description into the type (and the rest into the description), so a
documentation build shows a sentence where the type should be. These tests parse every public
docstring with :mod:`numpydoc.docscrape` and check:

- every entry of Parameters, Other Parameters, Returns, Yields, Receives, Raises, Warns and Attributes
  has a type that reads as a type: no `` -- `` in it and no sentence (no ending ``.``, ``;`` or ``:``);
- the names in Parameters (and Other Parameters) are the parameters of the signature, all of them: a
  documented name the function does not take, or a parameter missing from a section that exists, is
  reported by name (a callable without a Parameters section is not checked);
- numpydoc emits no warning (unknown section, bad underline) and raises no error.

"Public" is every name in the ``__all__`` of a public module (no component starting with ``_``) of the
three packages, defined in them, and the public methods and properties of the classes among those.
"""

import importlib
import inspect
import pathlib
import warnings

import pytest
from numpydoc.docscrape import ClassDoc, FunctionDoc, NumpyDocString

from conftest import defined_here, public_modules

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: The sections whose entries are ``name : type`` (or just ``type``) with a description below.
ENTRY_SECTIONS = ("Parameters", "Other Parameters", "Returns", "Yields", "Receives", "Raises", "Warns", "Attributes")


def documented_objects(module_name: str):
    """(qualified name, object, kind) of the module's public API: kind is "function", "class" or "property"."""
    module = importlib.import_module(module_name)
    for name in getattr(module, "__all__", ()):
        obj = getattr(module, name)
        if inspect.isclass(obj) and defined_here(obj):
            yield f"{module_name}.{name}", obj, "class"
            for member_name, member in vars(obj).items():
                if member_name.startswith("_"):
                    continue
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                if isinstance(member, property):
                    yield f"{module_name}.{name}.{member_name}", member, "property"
                elif inspect.isfunction(member):
                    yield f"{module_name}.{name}.{member_name}", member, "function"
        elif inspect.isfunction(obj) and defined_here(obj):
            yield f"{module_name}.{name}", obj, "function"


def parse(obj, kind):
    """The parsed docstring and the warnings numpydoc emitted while parsing it."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if kind == "class":
            doc = ClassDoc(obj, config={"show_class_members": False})
        elif kind == "function":
            doc = FunctionDoc(obj)
        else:
            doc = NumpyDocString(inspect.getdoc(obj) or "")
    return doc, [str(warning.message) for warning in caught]


def type_problem(entry_type: str) -> str | None:
    """Why ``entry_type`` is not a type numpydoc can show as one, or None."""
    if " -- " in entry_type:
        return "a ' -- ' description in the type"
    if entry_type.rstrip().endswith((".", ";", ":")):
        return "a sentence in the type"
    return None


def entry_problems(doc) -> list[str]:
    problems = []
    for section in ENTRY_SECTIONS:
        for entry in doc[section]:
            why = type_problem(entry.type)
            if why:
                label = f"{entry.name} : {entry.type}" if entry.name else entry.type
                problems.append(f"{section} entry {label[:90]!r}: {why}")
    return problems


def signature_names(obj, kind) -> list[str] | None:
    try:
        signature = inspect.signature(obj)
    except (TypeError, ValueError):  # a builtin without a signature
        return None
    names = list(signature.parameters)
    if kind == "function" and names and names[0] in ("self", "cls"):
        names = names[1:]
    return names


def documented_names(doc) -> list[str]:
    names = []
    for section in ("Parameters", "Other Parameters"):
        for entry in doc[section]:
            names.extend(part.strip().lstrip("*") for part in entry.name.split(","))
    return names


def parameter_problems(obj, kind, doc) -> list[str]:
    if not doc["Parameters"] or kind == "property":
        return []
    signature = signature_names(obj, kind)
    if signature is None:
        return []
    documented = documented_names(doc)
    problems = [f"documents {name!r}, which is not a parameter" for name in documented if name not in signature]
    problems += [f"parameter {name!r} is not documented" for name in signature if name not in documented]
    return problems


def module_problems(module_name: str, check) -> list[str]:
    problems = []
    for qualname, obj, kind in documented_objects(module_name):
        try:
            doc, caught = parse(obj, kind)
        except Exception as error:  # numpydoc raises ValueError for a section it cannot parse
            problems.append(f"{qualname}: numpydoc cannot parse it: {error}")
            continue
        problems.extend(f"{qualname}: {problem}" for problem in check(obj, kind, doc, caught))
    return problems


MODULES = public_modules()


def test_the_walk_finds_the_public_api():
    # A guard for the tests below: an empty walk would pass them vacuously. The three packages export
    # several hundred functions, classes, methods and properties (over a thousand names, counting each
    # public module that lists them); these two must be among them.
    found = {qualname for module in MODULES for qualname, _, _ in documented_objects(module)}
    assert len(found) > 300, len(found)
    assert {"meshing.TetMesh", "volspring.simulate"} <= found


@pytest.mark.parametrize("module_name", MODULES)
def test_entries_have_a_type_numpydoc_reads(module_name):
    problems = module_problems(module_name, lambda obj, kind, doc, caught: entry_problems(doc))
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("module_name", MODULES)
def test_documented_parameters_match_the_signature(module_name):
    problems = module_problems(module_name, lambda obj, kind, doc, caught: parameter_problems(obj, kind, doc))
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("module_name", MODULES)
def test_numpydoc_parses_without_warning(module_name):
    problems = module_problems(module_name, lambda obj, kind, doc, caught: caught)
    assert not problems, "\n".join(problems)


def test_the_checks_catch_the_old_layout():
    # A negative control: the layout these tests exist to refuse is caught, the numpydoc layout is not.
    def old(points, size):
        """Old layout.

        Parameters
        ----------
        points : (n, 3) float -- node positions [m]
        sizes : float -- edge length [m], wrapped over
            two lines

        Returns
        -------
        float -- the volume [m^3]

        Class attributes
        ----------------
        name : str
        """

    def new(points, size):
        """New layout.

        Parameters
        ----------
        points : (n, 3) float
            Node positions [m].
        size : float
            Edge length [m].

        Returns
        -------
        float
            The volume [m^3].
        """

    doc, caught = parse(old, "function")
    assert len(entry_problems(doc)) == 3
    assert parameter_problems(old, "function", doc) == ["documents 'sizes', which is not a parameter",
                                                       "parameter 'size' is not documented"]
    assert any("unknown section class attributes" in message.lower() for message in caught), caught
    doc, caught = parse(new, "function")
    assert entry_problems(doc) == [] and parameter_problems(new, "function", doc) == [] and caught == []
