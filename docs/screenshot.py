"""Screenshots of the built documentation site in headless Chromium (make docs-screenshot):
the front page and an API page, served on 127.0.0.1 from out/site, as PNGs in out/.

Needs a Chromium (Debian: apt-get install chromium); prints where the PNGs are. Exit status 1
when a page fails to render (Chromium's own error, or an empty PNG)."""
from __future__ import annotations

import functools
import http.server
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "out" / "site"
PAGES = {"docs-front.png": "", "docs-api-solver.png": "api/solver/"}
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--window-size=1400,1000"]


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):   # (no request log on stderr)
        pass


def main() -> int:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("docs-screenshot: no chromium on PATH (Debian: apt-get install chromium)")
        return 1
    if not (SITE / "index.html").exists():
        print(f"docs-screenshot: {SITE} not built (make docs)")
        return 1
    handler = functools.partial(_Quiet, directory=str(SITE))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    failed = 0
    try:
        for name, page in PAGES.items():
            out = ROOT / "out" / name
            with tempfile.TemporaryDirectory() as profile:
                subprocess.run([browser, *FLAGS, f"--user-data-dir={profile}",
                                f"--screenshot={out}", url + page], capture_output=True,
                               timeout=120)
            ok = out.exists() and out.stat().st_size > 10_000
            failed += not ok
            print(f"{url + page} -> {out}" + ("" if ok else " FAILED"))
    finally:
        server.shutdown()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
