"""MkDocs hooks of the documentation site (mkdocs.yml): the pages that live outside docs/ are
added as generated files, and the pages' code-formatted paths become links.

- ``index.md`` is the README (the first screen), ``changelog.md`` the CHANGELOG, and
  ``ros-interface/`` the message-level contract in ``msg_docs/`` (its README as the index): one
  source each, the repository's.
- ``run-times.md`` is generated from the catalogue's run times, measured by
  ``bench/bench_catalogue.py --write`` (``daddy_core/catalogue/run_times.json``).
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
    files.append(File.generated(config, "run-times.md", content=run_times_page()))
    return files


def run_times_page() -> str:
    """The catalogue's measured solve times as a page (``catalogue.run_times``)."""
    from daddy_core.catalogue import list_cases, load_case
    from daddy_core.catalogue.run_times import measured_on, read_run_times, solve_time
    rt = read_run_times()
    rows = ["| case | stages | energy-optimal | fuel-optimal | final mass (fuel) |",
            "|---|---|---|---|---|"]
    for name in list_cases():
        m = rt.get("cases", {}).get(name, {})
        energy, fuel = (solve_time(m[k]) if k in m else "—" for k in ("energy", "fuel"))
        mass = (m.get("fuel") or {}).get("final_mass_kg")
        rows.append(f"| `{name}` | {load_case(name).stages} | {energy} | {fuel} | "
                    f"{'—' if mass is None else f'{mass:.3f} kg'} |")
    return ("# Catalogue run times\n\nCPU per solve of every catalogue case from its cold "
            "guess, as `daddy list` shows them: generated from "
            "`daddy_core/catalogue/run_times.json`, which `bench/bench_catalogue.py --write` "
            f"measures ({measured_on(rt) or 'not measured'}; cap {rt.get('cap_s', '—')} s). "
            "Measurements, not a model: they age with the code and the machine. The solver's "
            "other figures are in `docs/benchmarks.md`.\n\n" + "\n".join(rows) + "\n")


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
