"""A real headless Chromium for the HTML report's tests (Debian: ``apt-get install chromium``).

The tests that use it skip, saying so, where ``/usr/bin/chromium`` is absent. Every run gets its
own profile directory, with background networking, QUIC, sync and component updates off (the
report needs no network: it is one self-contained file).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")

needs_chromium = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="no /usr/bin/chromium to render the report in a browser (Debian: apt-get install "
           "chromium)")

#: Appended to a copy of the page: after loading, the title holds the page's rendered height
#: and how many of its images the browser decoded (the report itself has no script).
PROBE = ("<script>window.onload=()=>{const i=[...document.images];document.title="
         "'height '+document.documentElement.scrollHeight+' decoded '+i.filter(x=>x.complete"
         "&&x.naturalWidth>100).length+' of '+i.length}</script>")


def chromium(*args: str, user_data: Path) -> subprocess.CompletedProcess[str]:
    """Run headless Chromium with ``args`` and its own profile in ``user_data``."""
    return subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", f"--user-data-dir={user_data}", *args],
        capture_output=True, text=True, timeout=120, check=False,
    )


def render(page: Path, work: Path, width: int = 1280) -> tuple[str, int, int, int]:
    """The DOM Chromium built from ``page`` at ``width`` px, the page's rendered height in px,
    and the images decoded and present."""
    probe = work / "probe.html"
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"),
                     encoding="utf-8")
    done = chromium(f"--window-size={width},900", "--virtual-time-budget=10000", "--dump-dom",
                    probe.as_uri(), user_data=work / "profile")
    shutil.rmtree(work / "profile", ignore_errors=True)
    assert done.returncode == 0, done.stderr[-2000:]
    m = re.search(r"<title>height (\d+) decoded (\d+) of (\d+)</title>", done.stdout)
    assert m, done.stdout[:500]
    return done.stdout, int(m.group(1)), int(m.group(2)), int(m.group(3))

