"""The public API's docstrings pass numpydoc's validation, and its entry points show a worked example.

The public API and the checks are defined once, in ``docs/_ext/public_api.py``,
which the Sphinx configuration reads too: ``make docs`` reports the same
failures as a warning (an error under ``-W``).
"""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

import pytest
from numpydoc.docscrape import get_doc_object
from numpydoc.validate import Validator, validate

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
import public_api  # noqa: E402  (the definition lives with the docs, not in the package)


def _names(entries) -> set[str]:
    # numpydoc lets one entry document several names: "A, B, C : ndarray"
    return {name.strip() for entry in entries for name in entry.name.split(",")}


def _attribute_errors(value, errors: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Accept a class's constructor parameters documented under Attributes (a result's fields), all of them."""
    doc = get_doc_object(value, config={"show_class_members": False})  # not the properties numpydoc would add
    attributes = doc["Attributes"]
    if not attributes:
        return errors
    # A protocol is never constructed: its signature is typing's (*args, **kwargs), not parameters of its own.
    signature = () if getattr(value, "_is_protocol", False) else Validator(doc).signature_parameters
    documented = _names(doc["Parameters"]) | _names(doc["Other Parameters"]) | _names(attributes)
    kept = [error for error in errors if error[0] != "PR01"]
    missing = [name for name in signature if name not in documented]
    if missing:
        kept.append(("PR01", f"Parameters {missing} documented neither as Parameters nor as Attributes"))
    for entry in attributes:
        if not entry.type:
            kept.append(("PR04", f'Attribute "{entry.name}" has no type'))
        if not "".join(entry.desc).strip():
            kept.append(("PR07", f'Attribute "{entry.name}" has no description'))
    return kept


def validation_errors(name: str, value) -> list[tuple[str, str]]:
    """The errors of the chosen checks on one definition's docstring."""
    report = validate(get_doc_object(inspect.unwrap(value)))
    errors = [error for error in report["errors"] if error[0] in public_api.VALIDATION_CHECKS]
    if inspect.isclass(value):
        errors = _attribute_errors(value, errors)
    return errors


PUBLIC = dict(public_api.public_objects())


def test_the_public_api_is_found():
    # An empty or shrunken list would pass the test below without checking anything.
    kinds = {"class": 0, "function": 0, "member": 0}
    for name, value in PUBLIC.items():
        kinds["class" if inspect.isclass(value) else "member" if name.count(".") > 2 else "function"] += 1
    assert kinds["class"] >= 80 and kinds["function"] >= 80 and kinds["member"] >= 250, kinds
    assert "vehid.identification.identify" in PUBLIC and "vehid.identification.IOData.split" in PUBLIC


def test_every_public_docstring_passes_numpydoc_validation():
    failures = [f"{name}: {code} {message}" for name, value in PUBLIC.items()
                for code, message in validation_errors(name, value)]
    assert not failures, f"{len(failures)} numpydoc validation errors:\n" + "\n".join(failures)


def test_a_missing_parameter_is_reported():
    # The check itself can fail: a function documenting one of its two parameters.
    def scaled(values, factor):
        """Return the values times a factor.

        Parameters
        ----------
        values : ndarray
            The values.

        Returns
        -------
        ndarray
            The scaled values.
        """
        return values * factor

    codes = [code for code, _ in validation_errors("scaled", scaled)]
    assert codes == ["PR01"]


def test_a_result_may_document_its_fields_as_attributes_but_all_of_them():
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Outcome:
        """An outcome.

        Attributes
        ----------
        fit : float
            Fit in percent.
        """

        fit: float
        seconds: float

    errors = validation_errors("Outcome", Outcome)
    assert [code for code, _ in errors] == ["PR01"] and "seconds" in errors[0][1] and "fit" not in errors[0][1]


@pytest.mark.parametrize("name", public_api.ENTRY_POINTS)
def test_entry_points_have_a_doctested_example(name):
    value = PUBLIC[name]
    examples = "\n".join(get_doc_object(inspect.unwrap(value))["Examples"])
    assert re.search(r"^\s*>>> ", examples, re.MULTILINE), f"{name} has no doctest in an Examples section"
    # tests/test_docs.py runs the examples of every module whose source holds '>>>'
    assert ">>>" in Path(inspect.getsourcefile(inspect.unwrap(value))).read_text(encoding="utf-8")
