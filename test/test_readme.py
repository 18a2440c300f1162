"""The README's and the documentation pages' Python examples run as written (a user copies them
first), and the README stays a first screen."""
import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCKS = [(page.relative_to(ROOT), i, block) for page in PAGES
          for i, block in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(), re.S))]


@pytest.mark.parametrize("page, index, block", BLOCKS, ids=[f"{p}-{i}" for p, i, _ in BLOCKS])
def test_documented_example_runs(page, index, block, capsys):
    exec(compile(block, f"{page} example {index}", "exec"), {"__name__": "readme"})
    assert capsys.readouterr().out.strip()      # each example prints its result


def test_the_readme_and_the_library_page_have_their_examples():
    assert sum(1 for p, _, _ in BLOCKS if p.name == "README.md") >= 1
    assert sum(1 for p, _, _ in BLOCKS if p.name == "library.md") >= 3


def test_the_readme_is_a_first_screen_and_links_pages_that_exist():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    for link in re.findall(r"`((?:docs/[\w.-]+\.md)|CHANGELOG\.md|msg_docs/)`", text):
        assert (ROOT / link).exists(), link
