"""A real browser for the explorer's tests: Debian's headless Chromium
driven by Selenium, and `denali explore` served from a subprocess.

No browser is downloaded: Chromium and its driver are Debian packages,
installed by scripts/ensure-debs when missing (as root or through sudo;
without either the test is skipped with the reason).
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import pytest
from conftest import REPO

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
DEBS = ("chromium", "chromium-driver")
# Headless, and nothing but the page: no updates, sync or first-run traffic.
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--window-size=1800,1300",
)  # fmt: skip
SERVER_START_S = 180  # importing torch and Dash on a loaded 2-core machine
WAIT_S = 60  # one page update, at most


def ensure_chromium() -> None:
    if CHROMIUM.exists() and CHROMEDRIVER.exists():
        return
    proc = subprocess.run([str(REPO / "scripts/ensure-debs"), *DEBS], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"cannot install {' '.join(DEBS)}: {proc.stderr.strip()[-500:]}")


@contextlib.contextmanager
def chromium(user_data_dir: Path) -> Iterator:
    """A Selenium driver of headless Chromium with a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={user_data_dir}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
    try:
        yield driver
    finally:
        driver.quit()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Server:
    url: str
    proc: subprocess.Popen
    log: Path

    def output(self) -> str:
        return self.log.read_text()


@contextlib.contextmanager
def explorer(results: Path, log: Path) -> Iterator[Server]:
    """`denali explore --results <results>` on a free local port, until the block ends."""
    port = _free_port()
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "denali_pipe.cli", "explore", "--results", str(results), "--host", "127.0.0.1", "--port", str(port)],
            stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip
    server = Server(f"http://127.0.0.1:{port}/", proc, log)
    try:
        deadline = time.monotonic() + SERVER_START_S
        while True:
            if proc.poll() is not None:
                raise AssertionError(f"denali explore exited with {proc.returncode}:\n{server.output()[-3000:]}")
            try:
                with urllib.request.urlopen(server.url, timeout=5) as r:
                    if r.status == 200:
                        break
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError(f"denali explore did not answer in {SERVER_START_S} s:\n{server.output()[-3000:]}") from None
                time.sleep(0.5)
        yield server
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def wait_for(driver, script: str, *args, timeout: float = WAIT_S):
    """Poll a JavaScript expression (a function body returning a value)
    until it returns something truthy, and return that."""
    deadline = time.monotonic() + timeout
    while True:
        value = driver.execute_script(script, *args)
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for: {script}")
        time.sleep(0.02)


# The figure of a dcc.Graph as Plotly drew it: its named traces' x, y and
# customdata (from _fullData, where Plotly has decoded the base64 arrays
# that plotly.py sends), its title and number of traces.
FIGURE_JS = """
const gd = document.querySelector('#' + arguments[0] + ' .js-plotly-plot');
if (!gd || !gd.data) return null;
const traces = {};
for (const t of gd._fullData) { if (t.name) traces[t.name] = {x: t.x ? Array.from(t.x) : null, y: t.y ? Array.from(t.y) : null,
                                                       customdata: t.customdata ? Array.from(t.customdata, c => Array.isArray(c) || ArrayBuffer.isView(c) ? Array.from(c) : c) : null}; }
const title = gd.layout.title ? (gd.layout.title.text || gd.layout.title) : '';
return {traces: traces, title: title, n_traces: gd.data.length};
"""

# A JavaScript condition: nothing is being recomputed (no component waits for a callback).
IDLE = "document.querySelector('[data-dash-is-loading=\"true\"]') === null"


def figure(driver, graph_id: str) -> dict:
    return wait_for(driver, FIGURE_JS, graph_id)


def text(driver, element_id: str) -> str:
    return driver.execute_script("const e = document.getElementById(arguments[0]); return e ? e.innerText : null;", element_id)


PANELS = ("frame", "histograms", "centre", "shape", "size-bars", "grid")  # the page's graphs
# Before a control change: the browser's clock, and a one-time listener on
# each graph for Plotly's event at the end of a redraw.
ARM_REDRAWN_JS = """
window._armed = performance.now(); window._redrawn = {};
for (const id of arguments[0]) {
  document.querySelector('#' + id + ' .js-plotly-plot').once('plotly_afterplot', () => { window._redrawn[id] = performance.now(); });
}
"""
# After it: milliseconds from the change to the last graph redrawn, once every one has been.
REDRAWN_JS = """
const done = arguments[0].map(id => window._redrawn[id]);
return done.every(t => t !== undefined) ? Math.max(...done) - window._armed : null;
"""
