"""MkDocs hooks of the documentation site (mkdocs.yml): the pages that live outside docs/ are
added as generated files, and the pages' code-formatted paths become links.

- ``index.md`` is the README (the first screen), ``changelog.md`` the CHANGELOG, and
  ``ros-interface/`` the message-level contract in ``msg_docs/`` (its README as the index): one
  source each, the repository's.
- In every page, outside fenced code, `docs/NAME.md` and `msg_docs/NAME.md` written in
  backticks (how the pages cite each other, readable on GitHub and in a terminal) become
  links to the site's page, which ``mkdocs build --strict`` then checks.
"""
from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
# repository file -> site page
GENERATED = {"README.md": "index.md", "CHANGELOG.md": "changelog.md",
             **{f"msg_docs/{p.name}": ("ros-interface/index.md" if p.name == "README.md"
                                       else f"ros-interface/{p.name}")
                for p in sorted((ROOT / "msg_docs").glob("*.md"))}}
CITED = re.compile(r"`((?:docs|msg_docs)/[\w.-]+\.md|CHANGELOG\.md)`")
FENCE = re.compile(r"^\s*(```|~~~)")


def site_page(repo_path: str) -> str | None:
    """The site page of a repository path cited in a page (None: not a page of the site)."""
    if repo_path.startswith("docs/"):
        return repo_path[len("docs/"):]
    if repo_path.startswith("msg_docs/"):   # (a page that is not there: a broken link, caught)
        return GENERATED.get(repo_path, "ros-interface/" + repo_path[len("msg_docs/"):])
    return GENERATED.get(repo_path)


def on_files(files, config):
    for src, dest in GENERATED.items():
        files.append(File.generated(config, dest, content=(ROOT / src).read_text()))
    return files


def on_page_markdown(markdown: str, page, config, files):
    here = posixpath.dirname(page.file.src_uri)
    out, fenced = [], False
    for line in markdown.split("\n"):
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            line = CITED.sub(lambda m: _link(m, here), line)
        out.append(line)
    return "\n".join(out)


def _link(m, here: str) -> str:
    target = site_page(m.group(1))
    if target is None:
        return m.group(0)
    return f"[{m.group(0)}]({posixpath.relpath(target, here or '.')})"
