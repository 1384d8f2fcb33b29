"""The README's picture of the live dashboard (``docs/dashboard.png``), made as the browser tests see it.

Runs ``skinet demo --live --dashboard PORT`` (the paper's unassisted run through simulated managers, CDR,
bridge, monitor and predictor), opens the page in headless Chromium and saves a PNG of the whole page
when the monitor shows ``--step`` (default 37: teleop started again after two violations, and SkiNet
flags the arm skill the operator starts next, the third violation) with its prediction fresh.  ``make screenshot`` runs it from the repository root::

    .venv/bin/python tests/screenshot.py -o docs/dashboard.png [--speed 4] [--step 37]

and prints what it photographed.  ``tests/services/test_dashboard.py`` checks it.  Needs Debian's
``chromium`` and ``chromium-driver`` (``scripts/install-test-deps.sh``) and selenium (the test extras);
without them it says so in one line and exits 1.
"""

from __future__ import annotations

import argparse
import base64
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from tests.loopback import free_port

REPO = Path(__file__).resolve().parents[1]
CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
                  "--disable-extensions")


class Unavailable(RuntimeError):
    """Chromium, its driver or selenium is missing."""


def chromium(width: int = 1500, height: int = 1900) -> Any:
    """A headless Chromium driven by selenium, its window ``width`` x ``height``; :class:`Unavailable` without it."""
    browser, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if browser is None or driver is None:
        raise Unavailable("Chromium is not installed (Debian packages chromium and chromium-driver; "
                          "scripts/install-test-deps.sh installs them)")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise Unavailable("selenium is not installed (pip install -e '.[test]')") from None
    options = Options()
    options.binary_location = browser
    for flag in (*CHROMIUM_FLAGS, f"--window-size={width},{height}"):
        options.add_argument(flag)
    out = webdriver.Chrome(service=Service(driver), options=options)
    out.set_page_load_timeout(20)
    return out


VIEWPORT_HEIGHT = 2400  # CSS pixels: taller than the page, so that nothing scrolls


def tall_viewport(driver: Any, width: int) -> None:
    """Lay the page out in a viewport ``width`` wide and taller than the page (Chrome DevTools)."""
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                           {"width": width, "height": VIEWPORT_HEIGHT, "deviceScaleFactor": 1, "mobile": False})


def page_png(driver: Any, width: int) -> bytes:
    """A PNG of the page as shown now, down to the end of its content."""
    height = driver.execute_script("return Math.ceil(document.querySelector('main').getBoundingClientRect().bottom)")
    shot = driver.execute_cdp_cmd("Page.captureScreenshot", {
        "format": "png", "clip": {"x": 0, "y": 0, "width": width, "height": int(height), "scale": 1}})
    return base64.b64decode(shot["data"])


SHOWN = """
const v = view.verdicts;
return {seq: view.state ? view.state.seq : -1, fresh: !!view.unsafe && !view.unsafe.prediction_stale
        && view.unsafe.seq === (view.state && view.state.seq),
        violated: v ? v.properties.filter((p) => !p.holds).map((p) => p.name) : [],
        violations: view.violations.filter(Boolean).length};"""


class MovedOn(RuntimeError):
    """The page drew a later step while it was photographed (a loaded machine at this speed)."""


ATTEMPTS = 3  # photographs tried, each at half the speed of the one before, while the page moves on


def photograph(output: Path, speed: float, step: int, width: int, timeout: float = 120.0) -> str:
    """Run the live demo, photograph its page at ``step`` into ``output``; returns what was photographed."""
    port = free_port()
    demo = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "demo", "--live", "--dashboard", str(port),
                             "--speed", f"{speed:g}", "--linger", "60"], cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    driver = None
    try:
        first = demo.stderr.readline().strip()  # type: ignore[union-attr]
        if first != f"dashboard on http://127.0.0.1:{port}/":
            raise RuntimeError(f"skinet demo --live did not start: {first or demo.wait(10)}")
        driver = chromium(width, 1000)
        tall_viewport(driver, width)
        driver.get(f"http://127.0.0.1:{port}/")
        deadline = time.monotonic() + timeout
        while True:
            shown = driver.execute_script(SHOWN)
            if shown["seq"] >= step and shown["fresh"]:  # drawn at the next frame (the page redraws per frame)
                driver.execute_script("return new Promise((done) => requestAnimationFrame(() => done()))")
                break
            if time.monotonic() > deadline or demo.poll() is not None:
                raise RuntimeError(f"the dashboard never showed step {step} with a fresh prediction (it showed {shown})")
            time.sleep(0.05)
        png = page_png(driver, width)
        if driver.execute_script(SHOWN) != shown:
            raise MovedOn(f"the page moved on from step {shown['seq']} while it was photographed: run it again, "
                          "or with a lower --speed")
    finally:
        if driver is not None:
            driver.quit()
        demo.terminate()
        demo.wait(30)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_bytes(png)
    w, h = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")  # the PNG's IHDR
    return (f"{output}: {w}x{h} PNG of the live dashboard at step {shown['seq']}, {shown['violations']} violations, "
            f"violated now: {', '.join(shown['violated']) or 'none'}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="tests/screenshot.py", description=__doc__.split("\n\n")[0])
    p.add_argument("-o", "--output", type=Path, default=REPO / "docs" / "dashboard.png", help="PNG to write")
    p.add_argument("--speed", type=float, default=4.0, help="time scale of the live demo (default: 4)")
    p.add_argument("--step", type=int, default=37, help="the monitor step to photograph (default: 37)")
    p.add_argument("--width", type=int, default=1400, help="page width in pixels (default: 1400)")
    args = p.parse_args(argv)
    try:
        for attempt in range(ATTEMPTS):
            try:
                print(photograph(args.output, args.speed / 2 ** attempt, args.step, args.width))
                break
            except MovedOn:
                if attempt == ATTEMPTS - 1:
                    raise
    except (Unavailable, RuntimeError) as exc:
        print(f"tests/screenshot.py: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
