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


def _exists(module_path: pathlib.Path, name: str) -> bool:
    """``name`` is defined at the top level of the module (def, class or assignment), or is a
    dataclass field / method of one of its classes (``Class.field``)."""
    import ast
    tree = ast.parse(module_path.read_text())
    head, _, attr = name.partition(".")
    for node in tree.body:
        names = ([t.id for t in node.targets if isinstance(t, ast.Name)]
                 if isinstance(node, ast.Assign) else [getattr(node, "name", None)])
        if head in names:
            if not attr:
                return True
            return any(getattr(n, "name", None) == attr or
                       (isinstance(n, ast.AnnAssign) and n.target.id == attr)
                       for n in node.body)
    return False


def test_the_algorithm_map_names_functions_that_exist():
    """Every `path`: `name` of docs/algorithm-map.md is a definition in that module."""
    text = (ROOT / "docs" / "algorithm-map.md").read_text()
    pairs = re.findall(r"`((?:daddy_core/)?[\w/]+\.py)`: ([^|;]+)", text)
    assert len(pairs) >= 20
    for path, names in pairs:
        module = ROOT / (path if path.startswith("daddy_core/") else f"daddy_core/{path}")
        assert module.exists(), path
        for name in re.findall(r"`(\w+(?:\.\w+)?)", names):
            assert _exists(module, name), f"{path}: {name}"


def test_every_design_note_names_code_and_tests_that_exist():
    """Each safeguard row of docs/design-notes.md names code (`module.name`, `XOptions.field`)
    and tests (`test_file.py::test_name`) that exist."""
    text = (ROOT / "docs" / "design-notes.md").read_text()
    rows = [r for r in text.splitlines() if r.startswith("| ") and not r.startswith("| safeguard")]
    assert len(rows) >= 19
    solver = ROOT / "daddy_core" / "solver"
    for row in rows:
        tests = re.findall(r"`(test_\w+\.py)::(test_\w+)`", row)
        assert tests, row
        for file, name in tests:
            assert f"def {name}(" in (ROOT / "test" / file).read_text(), (file, name)
        for module, name in re.findall(r"`(\w+)\.(\w+)`", row):
            if (solver / f"{module}.py").exists():
                assert _exists(solver / f"{module}.py", name), (module, name)
            elif module.endswith("Options"):
                assert _exists(solver / "options.py", f"{module}.{name}"), (module, name)
