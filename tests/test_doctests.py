"""The examples in the public API's docstrings run as written (as python-control runs
its docstrings' examples): every ``>>>`` line of every public name of the four packages
and of its methods, through doctest, in a fresh namespace.  The names a plug-in author
and a first-time user reach for first carry an example (issue 47: the whole API had four
``>>>`` lines, none of them run)."""
import doctest
import importlib
import inspect

import pytest

PACKAGES = ("validation", "reduced_model", "plant_exudyn", "controllers")
#: Names whose docstrings must show an example.
WITH_EXAMPLES = {"resolve", "CompiledLaw", "compiled_form", "PaperSMO", "PaperReference",
                 "QuinticMove", "run_scenario", "scenario_from_mapping", "RunResult",
                 "run_campaign", "Campaign", "nu_gap", "stability_margin", "FieldError",
                 "natural_frequencies", "check_sample_time", "validate_modes_per_link"}
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def public_tests():
    """(id, doctest) for every public name's docstring examples (methods included)."""
    finder = doctest.DocTestFinder(recurse=True, exclude_empty=True)
    seen = set()
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)) or id(obj) in seen:
                continue
            seen.add(id(obj))
            for test in finder.find(obj, f"{package}.{name}", module=inspect.getmodule(obj),
                                    globs={}):
                if test.examples:
                    yield test.name, test


TESTS = dict(public_tests())


def test_the_names_users_reach_for_first_have_examples():
    named = {key.split(".")[1] for key in TESTS}
    assert WITH_EXAMPLES <= named, f"no example: {sorted(WITH_EXAMPLES - named)}"


@pytest.mark.parametrize("name", sorted(TESTS))
def test_docstring_examples_run(name):
    report: list[str] = []
    result = doctest.DocTestRunner(optionflags=FLAGS).run(TESTS[name], out=report.append)
    assert result.failed == 0, "".join(report)
