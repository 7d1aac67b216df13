"""The preview page in a real browser (Debian's headless chromium through selenium) against a
real server: it loads without console errors, animates an uploaded BVH locally, and shows
the problem detail when the POST fails (no model endpoint serves it yet, or bad input).

Skips with the reason when chromium or chromedriver is absent
(``apt-get install chromium chromium-driver``; ``.ci/run`` does it).
"""

from __future__ import annotations

import re
import shutil
import time
from pathlib import Path

import pytest

from motion import bvh
from tests.server import REPO, ServerProcess

FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver") or (
    "/usr/bin/chromedriver" if Path("/usr/bin/chromedriver").exists() else None
)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="chromium/chromedriver not installed (apt-get install chromium chromium-driver)",
)

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",  # software WebGL without a deprecation warning
    "--window-size=1280,900",
]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    log = tmp_path_factory.mktemp("browser") / "server.log"
    with ServerProcess(env={"MOTION_LOG_LEVEL": "warning"}, log_path=log) as running:
        yield running


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()


def wait_for(driver, script: str, timeout: float = 20.0):
    """Poll ``return <script>`` until it is truthy; returns its value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = driver.execute_script(f"return {script}")
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {script}")


def console_errors(driver, *, allow_network: bool = False) -> list[dict]:
    entries = driver.get_log("browser")
    return [
        e
        for e in entries
        if e["level"] == "SEVERE" and not (allow_network and e.get("source") == "network")
    ]


def test_page_animates_an_uploaded_clip_and_reports_problems(server, browser, tmp_path):
    from selenium.webdriver.common.by import By

    browser.get(server.url + "/")
    wait_for(browser, "window.motionPreview && window.motionPreview.input")
    wait_for(browser, "document.querySelector('#style-name option') !== null")
    assert console_errors(browser) == []
    webgl = browser.execute_script("return window.motionPreview.webgl")

    # Upload the fixture: it is parsed and animated in the browser, no server needed.
    browser.find_element(By.ID, "content-file").send_keys(str(FIXTURE))
    wait_for(browser, "window.motionPreview.input.loaded")
    state = browser.execute_script("return window.motionPreview.input")
    assert state["frames"] == 60 and state["fps"] == 30
    assert "cmu_02_01_walk_30fps.bvh: 60 frames" in browser.find_element(By.ID, "input-info").text

    seen = set()
    view = browser.find_element(By.ID, "input-view")
    shots = [view.screenshot_as_png]
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and len(seen) < 5:
        seen.add(browser.execute_script("return window.motionPreview.input.frame"))
        time.sleep(0.1)
    shots.append(view.screenshot_as_png)
    assert len(seen) >= 5, f"the frame counter did not advance: {seen}"
    if webgl:
        assert shots[0] != shots[1], "the canvas did not change between two screenshots"
    assert console_errors(browser) == []

    # Run with the selected style: the shipped model answers, the result animates beside
    # the input, and the download is a valid BVH on the input's own skeleton.
    browser.find_element(By.ID, "run").click()
    wait_for(browser, "window.motionPreview.result.loaded", timeout=90)
    result = browser.execute_script("return window.motionPreview.result")
    assert result["frames"] >= 2 and result["fps"] == 30
    seen = set()
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and len(seen) < 5:
        seen.add(browser.execute_script("return window.motionPreview.result.frame"))
        time.sleep(0.1)
    assert len(seen) >= 5, f"the result did not animate: {seen}"
    link = browser.find_element(By.ID, "download")
    assert link.get_attribute("hidden") is None
    assert link.get_attribute("href").startswith("blob:")
    saved = browser.execute_script("return window.motionPreview.download")
    assert saved["name"].endswith(".bvh") and link.get_attribute("download") == saved["name"]
    out = bvh.loads(saved["text"])
    assert out.skeleton.names == bvh.load(FIXTURE).skeleton.names
    assert console_errors(browser) == []

    # A skeleton the service cannot map: the page shows the problem's title, status,
    # detail and request id, offers no download, and the input keeps playing.
    names = bvh.load(FIXTURE).skeleton.names
    odd = FIXTURE.read_text()
    for i, name in sorted(enumerate(names), key=lambda p: -len(p[1])):
        odd = re.sub(rf"\b(ROOT|JOINT) {re.escape(name)}\b", rf"\1 bone{i}", odd)
    odd_path = tmp_path / "not_humanoid.bvh"
    odd_path.write_text(odd)
    browser.find_element(By.ID, "content-file").send_keys(str(odd_path))
    wait_for(browser, "window.motionPreview.input.loaded")
    browser.find_element(By.ID, "run").click()
    message = wait_for(
        browser,
        "document.querySelector('#message.error') && "
        "document.querySelector('#message').textContent",
        timeout=60,
    )
    assert re.search(r"failed: .+ \(4\d\d\) - .+ - request id [0-9a-f]{32}", message), message
    assert browser.find_element(By.ID, "download").get_attribute("hidden") is not None
    assert console_errors(browser, allow_network=True) == []
    before = browser.execute_script("return window.motionPreview.input.ticks")
    time.sleep(0.3)
    assert browser.execute_script("return window.motionPreview.input.ticks") > before


def test_a_file_that_is_not_bvh_is_reported_not_thrown(server, browser, tmp_path):
    from selenium.webdriver.common.by import By

    bad = tmp_path / "notes.bvh"
    bad.write_text("this is not a motion file\n")
    browser.get(server.url + "/")
    wait_for(browser, "window.motionPreview && window.motionPreview.input")
    browser.get_log("browser")  # drop what the earlier page logged
    browser.find_element(By.ID, "content-file").send_keys(str(bad))
    message = wait_for(
        browser,
        "document.querySelector('#message.error') && "
        "document.querySelector('#message').textContent",
    )
    assert "Could not read notes.bvh as BVH" in message
    assert console_errors(browser) == []
    assert browser.execute_script("return window.motionPreview.input.loaded") is False
