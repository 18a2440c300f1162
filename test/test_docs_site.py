"""The documentation site (mkdocs.yml, ``make docs``) and the code blocks of its pages.

The site builds with warnings as errors (every nav entry, link and anchor resolved by MkDocs,
every API page rendered from the docstrings) and no link of the built HTML points to a file
that is not there. The Python blocks of README.md and docs/ run in ``test_readme.py``, the one
of msg_docs/ against a node in ``test_replan_action.py``; here the other blocks: every shell command of ours parses with its own argument parser (``make``
targets exist, bench scripts answer ``--help``), JSON case files load, a campaign file in YAML
validates, and the message examples in YAML parse."""
import html.parser
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote, urlparse

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
         *sorted((ROOT / "msg_docs").glob("*.md"))]


def _blocks(lang: str):
    return [(p.relative_to(ROOT), b) for p in PAGES
            for b in re.findall(rf"```{lang}\n(.*?)```", p.read_text(), re.S)]


# --------------------------------------------------------------------------------- the site


class _Links(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.links = []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("href", "src") and value:
                self.links.append(value)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs", reason="the docs extra (make test installs it)")
    pytest.importorskip("mkdocstrings", reason="the docs extra (make test installs it)")
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                           str(out)], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_the_site_builds_strict_with_every_page(site):
    for page in ("index.html", "getting-started/index.html", "library/index.html",
                 "algorithm-map/index.html", "design-notes/index.html", "cli/index.html",
                 "ros-interface/index.html", "ros-interface/replan_action/index.html",
                 "campaigns/index.html", "reliability/index.html", "benchmarks/index.html",
                 "changelog/index.html", "run-times/index.html", "api/solver/index.html"):
        assert (site / page).exists(), page
    front = (site / "index.html").read_text()
    assert "Two commands" in front and 'href="benchmarks/"' in front   # the README, linked
    assert "earth_mars" in (site / "run-times" / "index.html").read_text()   # from bench/
    api = (site / "api" / "solver" / "index.html").read_text()
    assert "u_guess" in api and "SolverOptions" in api and "fuel_step" in api


def test_no_link_of_the_built_site_is_broken(site):
    broken = []
    for page in site.rglob("*.html"):
        parser = _Links()
        parser.feed(page.read_text())
        for link in parser.links:
            url = urlparse(link)
            if url.scheme or url.netloc or link.startswith(("#", "mailto:")):
                continue
            base = site if url.path.startswith("/") else page.parent   # (404.html: absolute)
            target = (base / unquote(url.path).lstrip("/")).resolve()
            if url.path.endswith("/") or target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{page.relative_to(site)}: {link}")
    assert not broken, broken[:20]


# --------------------------------------------------------------------------------- shell blocks


def _commands():
    """(page, argv) of every command line in the pages' sh blocks (continuations joined,
    comments and environment assignments removed, ``[optional]`` brackets dropped)."""
    out = []
    for page, block in _blocks("(?:sh|bash)"):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split("  #")[0].split(" # ")[0].strip()
            line = re.sub(r"\[([^\]]*)\]", r"\1", line)
            argv = shlex.split(line)
            while argv and re.match(r"^[A-Z_][A-Z0-9_]*=", argv[0]):
                argv = argv[1:]
            if argv:
                out.append((page, argv))
    return out


def _parse(argv):
    """Parse argv with the parser of the program it names; None: a program not ours."""
    prog = argv[0].removeprefix(".venv/bin/")
    if prog == "make":
        targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M))
        missing = [t for t in argv[1:] if "=" not in t and t not in targets]
        assert not missing, f"make targets not in the Makefile: {missing}"
        return True
    if prog == "python" and argv[1:3] == ["-m", "daddy_core"]:
        prog, argv = "daddy", argv[2:]
    if prog == "python" and argv[1].startswith("bench/"):
        proc = subprocess.run([sys.executable, argv[1], "--help"], cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return True
    if prog == "daddy":
        from daddy_core.cli import _parser
        parser = _parser()
    elif prog == "daddy_campaign":
        from daddy_sim.campaign_cli import build_parser
        parser = build_parser()
    elif prog == "ros2":   # ros2 run PACKAGE EXECUTABLE --ros-args --params-file FILE
        assert argv[1:4] == ["run", "daddy_ros", "guidance_node"], argv
        assert "guidance_node = daddy_ros.guidance_node:main" in (ROOT / "setup.py").read_text()
        assert (ROOT / argv[argv.index("--params-file") + 1]).exists()
        return True
    else:
        return None   # export, dask: not ours
    try:
        parser.parse_args(argv[1:])
    except SystemExit as exc:
        pytest.fail(f"{' '.join(argv)}: the parser refused it (exit {exc.code})")
    return True


COMMANDS = _commands()


@pytest.mark.parametrize("page, argv", COMMANDS,
                         ids=[f"{p}:{' '.join(a)[:40]}" for p, a in COMMANDS])
def test_every_documented_command_of_ours_parses(page, argv):
    _parse(argv)


def test_the_commands_cover_every_program_of_ours():
    programs = {a[0].removeprefix(".venv/bin/") for _, a in COMMANDS if _parse(a)}
    assert {"make", "daddy", "daddy_campaign", "ros2", "python"} <= programs


# --------------------------------------------------------------------------------- data blocks


def test_documented_case_files_load():
    from daddy_core.catalogue import case_from_dict
    from daddy_core.catalogue.sail_cases import sail_case_from_dict
    loaded = 0
    for page, block in _blocks("json"):
        text = block.strip()
        if not text.startswith("{"):
            text = "{" + text.rstrip(",") + "}"   # a fragment of keys: still JSON
        data = json.loads(text)
        if "system" in data:
            (sail_case_from_dict if data["system"] == "earth_sail" else case_from_dict)(data)
            loaded += 1
    assert loaded >= 1


def test_documented_yaml_parses_and_the_campaign_file_validates():
    yaml = pytest.importorskip("yaml")
    from daddy_sim.campaigns import CampaignConfig
    blocks = _blocks("yaml")
    assert blocks
    for page, block in blocks:
        data = yaml.safe_load(block)
        if page.name == "campaigns.md":
            CampaignConfig.from_dict(data, where=str(page))
