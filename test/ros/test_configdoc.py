"""docs/configuration.md is the configuration reference of the code as it is: regenerated from the
config dataclasses it is the same page, and it names every key of every config a user writes."""

import dataclasses

import pytest

from mrslam_ros import configdoc

pytestmark = pytest.mark.ros


def test_the_reference_page_matches_the_dataclasses():
    page = configdoc.PAGE.read_text()
    assert page == configdoc.render(), "run: python -m mrslam_ros.configdoc --write"
    for spec, _ in configdoc.TOP:
        cls = configdoc._load(spec)
        assert f"## {cls.__name__}" in page
        for f in dataclasses.fields(cls):
            assert f"| `{f.name}` |" in page, (cls.__name__, f.name)


def test_attribute_docs_read_google_style_sections():
    @dataclasses.dataclass(frozen=True)
    class Example:
        """An example.

        Attributes:
            a, b: two values that share
                a description [m].
            c: the third.
        """

        a: int = 1
        b: int = 2
        c: float = 0.5  # not read: the docstring wins

    assert configdoc.attribute_docs(Example) == {"a": "two values that share a description [m].",
                                                 "b": "two values that share a description [m].", "c": "the third."}
