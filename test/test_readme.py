"""The README's Python examples run as written (a user copies them first)."""
import pathlib
import re

import pytest

README = pathlib.Path(__file__).parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_example_runs(index, capsys):
    exec(compile(BLOCKS[index], f"README.md example {index}", "exec"), {"__name__": "readme"})
    assert capsys.readouterr().out.strip()      # each example prints its result


def test_the_readme_has_its_examples():
    assert len(BLOCKS) >= 3
