"""The preview page in a real browser (Debian's headless chromium through selenium) against a
real server: it loads without console errors, lists the styles by family (translator,
registered, fast), animates an uploaded BVH or GLB locally, plays input and result on one
timeline (play/pause, scrubbing), runs a registered style, gives the result back in the
input's format for download, and shows the problem detail when the POST fails; where the
service needs an API key, it asks for one and works with it.

Skips with the reason when chromium or chromedriver is absent
(``apt-get install chromium chromium-driver``; ``.ci/run`` does it).
"""

from __future__ import annotations

import base64
import re
import shutil
import time
from pathlib import Path

import httpx
import pytest

from motion import bvh, gltf
from service import api_keys
from tests.gltf_files import character_glb
from tests.server import REPO, ServerProcess

FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver") or (
    "/usr/bin/chromedriver" if Path("/usr/bin/chromedriver").exists() else None
)
# a pelvis and a tail: BVH the browser reads, a skeleton no humanoid mapping fits (422)
NOT_HUMANOID = (
    "HIERARCHY\nROOT Pelvis\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition"
    " Zrotation Xrotation Yrotation\n JOINT Tail\n {\n  OFFSET 0 -10 0\n  CHANNELS 3"
    " Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -5 0\n  }\n }\n}\n"
    "MOTION\nFrames: 3\nFrame Time: 0.0333333\n"
    + "".join(f"0 {k} 0 {10 * k} 0 0 {5 * k} 0 0\n" for k in range(3))
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
    folder = tmp_path_factory.mktemp("browser")
    env = {"MOTION_LOG_LEVEL": "warning", "MOTION_STYLES_DIR": str(folder / "styles")}
    with ServerProcess(env=env, log_path=folder / "server.log") as running:
        r = httpx.post(
            running.url + "/v1/styles",
            data={"name": "studio-walk"},
            files=[("clips", ("walk.bvh", FIXTURE.read_bytes(), "text/plain"))],
            timeout=60,
        )
        assert r.status_code == 201, r.text
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


def frames_seen(driver, view: str, seconds: float = 3.0) -> set[int]:
    seen = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and len(seen) < 5:
        seen.add(driver.execute_script(f"return window.motionPreview.{view}.frame"))
        time.sleep(0.1)
    return seen


def open_page(server, browser) -> None:
    browser.get(server.url + "/")
    wait_for(browser, "window.motionPreview && window.motionPreview.input")
    wait_for(browser, "document.querySelector('#style-name option') !== null")


def run_and_wait(browser) -> dict:
    from selenium.webdriver.common.by import By

    browser.execute_script("window.motionPreview.result.loaded = false")
    browser.find_element(By.ID, "run").click()
    wait_for(browser, "window.motionPreview.result.loaded", timeout=90)
    return browser.execute_script("return window.motionPreview.result")


def scrub(browser, fraction: float) -> float:
    """Move the shared timeline to ``fraction`` of its length as a user would (an input
    event); returns the time the page is at."""
    browser.execute_script(
        "const t = document.getElementById('timeline');"
        f"t.value = String(Math.round({fraction} * Number(t.max)));"
        "t.dispatchEvent(new Event('input'));"
    )
    return browser.execute_script("return window.motionPreview.time")


def test_page_plays_input_and_result_on_one_timeline_and_reports_problems(
    server, browser, tmp_path
):
    from selenium.webdriver.common.by import By

    open_page(server, browser)
    assert console_errors(browser) == []
    webgl = browser.execute_script("return window.motionPreview.webgl")

    # Styles by family: the translator's, the registered one, the fast networks'.
    groups = browser.execute_script(
        "return [...document.querySelectorAll('#style-name optgroup')].map(g =>"
        " [g.dataset.group, [...g.querySelectorAll('option')].map(o => o.value)])"
    )
    assert [g for g, _ in groups] == ["translator", "registered", "fast"]
    by_group = dict(groups)
    assert by_group["registered"] == ["studio-walk"]
    assert "studio-walk" not in by_group["translator"] and "elderly" in by_group["translator"]
    assert "angry" in by_group["fast"]

    # Upload the fixture: it is parsed and animated in the browser, no server needed.
    browser.find_element(By.ID, "content-file").send_keys(str(FIXTURE))
    wait_for(browser, "window.motionPreview.input.loaded")
    state = browser.execute_script("return window.motionPreview.input")
    assert state["frames"] == 60 and state["fps"] == 30 and state["format"] == "bvh"
    assert "cmu_02_01_walk_30fps.bvh: 60 frames" in browser.find_element(By.ID, "input-info").text

    view = browser.find_element(By.ID, "input-view")
    shots = [view.screenshot_as_png]
    seen = frames_seen(browser, "input")
    shots.append(view.screenshot_as_png)
    assert len(seen) >= 5, f"the frame counter did not advance: {seen}"
    if webgl:
        assert shots[0] != shots[1], "the canvas did not change between two screenshots"
    assert console_errors(browser) == []

    # Pause: the input holds its frame; the timeline moves it; Play goes on.
    play = browser.find_element(By.ID, "play")
    play.click()
    assert browser.execute_script("return window.motionPreview.playing") is False
    assert play.text == "Play"
    held = browser.execute_script("return window.motionPreview.input.frame")
    time.sleep(0.4)
    assert browser.execute_script("return window.motionPreview.input.frame") == held
    duration = browser.execute_script("return window.motionPreview.duration")
    assert duration == pytest.approx(59 / 30, abs=1e-3)
    at = scrub(browser, 0.5)
    assert at == pytest.approx(duration / 2, abs=duration / 500)
    assert browser.execute_script("return window.motionPreview.input.frame") == int(at * 30 + 1e-6)
    assert f"{at:.2f} / {duration:.2f} s" == browser.find_element(By.ID, "time").text
    play.click()
    assert len(frames_seen(browser, "input")) >= 5

    # Run with the selected style (the first translator style): the result animates beside
    # the input, and the download is a BVH (the input's format) on the input's skeleton.
    result = run_and_wait(browser)
    assert result["frames"] >= 2 and result["fps"] == 30 and result["format"] == "bvh"
    assert len(frames_seen(browser, "result")) >= 5, "the result did not animate"
    link = browser.find_element(By.ID, "download")
    assert link.get_attribute("hidden") is None
    assert link.get_attribute("href").startswith("blob:")
    saved = browser.execute_script("return window.motionPreview.download")
    assert saved["name"].endswith(".bvh") and link.get_attribute("download") == saved["name"]
    assert saved["type"] == "text/plain" and "BVH" in link.text
    out = bvh.loads(saved["text"])
    assert out.skeleton.names == bvh.load(FIXTURE).skeleton.names
    assert console_errors(browser) == []

    # One timeline for both: it spans the longer clip, and paused at a time each view shows
    # its own frame of that time (the shorter one holds its last).
    play.click()
    both = browser.execute_script("return window.motionPreview")
    longest = max(59 / 30, (result["frames"] - 1) / 30)
    assert both["duration"] == pytest.approx(longest, abs=1e-3)
    for fraction in (0.25, 0.9):
        at = scrub(browser, fraction)
        frames = browser.execute_script(
            "return [window.motionPreview.input.frame, window.motionPreview.result.frame]"
        )
        expected = [min(59, int(at * 30 + 1e-6)), min(result["frames"] - 1, int(at * 30 + 1e-6))]
        assert abs(frames[0] - expected[0]) <= 1 and abs(frames[1] - expected[1]) <= 1
    play.click()

    # The registered style, picked from its group, runs through /v1/transfer.
    browser.execute_script(
        "const s = document.getElementById('style-name'); s.value = 'studio-walk';"
        "s.dispatchEvent(new Event('change'));"
    )
    registered = run_and_wait(browser)
    assert registered["frames"] >= 2
    assert "Done:" in browser.execute_script("return window.motionPreview.lastMessage")

    # A skeleton the service cannot map: the page shows the problem's title, status,
    # detail and request id, offers no download, and the input keeps playing.
    odd_path = tmp_path / "not_humanoid.bvh"
    odd_path.write_text(NOT_HUMANOID)
    browser.find_element(By.ID, "content-file").send_keys(str(odd_path))
    wait_for(
        browser, "window.motionPreview.input.loaded && window.motionPreview.input.frames === 3"
    )
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


def test_a_glb_character_goes_in_and_comes_back_as_glb(server, browser, tmp_path):
    from selenium.webdriver.common.by import By

    walk = bvh.load(FIXTURE)
    path = tmp_path / "character.glb"
    path.write_bytes(character_glb(walk))
    open_page(server, browser)
    browser.get_log("browser")
    browser.find_element(By.ID, "content-file").send_keys(str(path))
    wait_for(browser, "window.motionPreview.input.loaded")
    state = browser.execute_script("return window.motionPreview.input")
    assert state["frames"] == 60 and state["fps"] == 30 and state["format"] == "glb"
    assert len(frames_seen(browser, "input")) >= 5

    result = run_and_wait(browser)
    assert result["format"] == "glb" and result["frames"] >= 2
    saved = browser.execute_script(
        "const d = window.motionPreview.download; let s = '';"
        "for (let i = 0; i < d.bytes.length; i += 1) s += String.fromCharCode(d.bytes[i]);"
        "return {name: d.name, type: d.type, base64: btoa(s)};"
    )
    link = browser.find_element(By.ID, "download")
    assert saved["name"].endswith(".glb") and link.get_attribute("download") == saved["name"]
    assert saved["type"] == "model/gltf-binary" and "GLB" in link.text
    out = gltf.loads(base64.b64decode(saved["base64"]))
    assert out.skeleton.names == walk.skeleton.names
    assert out.num_frames == result["frames"]
    assert console_errors(browser) == []


def test_the_services_warnings_are_shown_with_the_result(server, browser, tmp_path):
    """A style clip of 5 frames: the result plays, and the message under the controls
    gives the service's warning (``X-Warnings``) that such a clip carries less style."""
    from selenium.webdriver.common.by import By

    short = tmp_path / "short_style.bvh"
    bvh.save(bvh.load(FIXTURE).slice(0, 5), short)
    open_page(server, browser)
    browser.find_element(By.ID, "content-file").send_keys(str(FIXTURE))
    wait_for(browser, "window.motionPreview.input.loaded")
    browser.find_element(By.ID, "style-file").send_keys(str(short))
    assert (
        browser.execute_script(
            "return document.querySelector('input[name=\"mode\"]:checked').value"
        )
        == "clip"
    )
    assert run_and_wait(browser)["frames"] >= 2
    message = browser.find_element(By.ID, "message")
    assert message.get_attribute("class") == "warning"
    assert "Done:" in message.text and "Warning: the style clip lasts 0.17 s" in message.text
    assert console_errors(browser) == []


def test_a_file_that_is_neither_bvh_nor_gltf_is_reported_not_thrown(server, browser, tmp_path):
    from selenium.webdriver.common.by import By

    bad = tmp_path / "notes.bvh"
    bad.write_text("this is not a motion file\n")
    open_page(server, browser)
    browser.get_log("browser")  # drop what the earlier page logged
    browser.find_element(By.ID, "content-file").send_keys(str(bad))
    message = wait_for(
        browser,
        "document.querySelector('#message.error') && "
        "document.querySelector('#message').textContent",
    )
    assert "Could not read notes.bvh as BVH or glTF" in message
    assert console_errors(browser) == []
    assert browser.execute_script("return window.motionPreview.input.loaded") is False


@pytest.fixture(scope="module")
def keyed_server(tmp_path_factory):
    """A service that needs an API key, and the key of ``preview`` (scope ``use``)."""
    folder = tmp_path_factory.mktemp("browser-keys")
    key = api_keys.add_key(folder / "api-keys", "preview", frozenset({"use"}))
    env = {"MOTION_LOG_LEVEL": "warning", "MOTION_API_KEYS_FILE": str(folder / "api-keys")}
    with ServerProcess(env=env, log_path=folder / "server.log") as running:
        yield running, key


def test_the_page_asks_for_a_key_where_the_service_needs_one(server, keyed_server, browser):
    from selenium.webdriver.common.by import By

    open_page(server, browser)  # a service without keys: no key asked for
    assert not browser.find_element(By.ID, "key-form").is_displayed()
    assert browser.execute_script("return window.motionPreview.needsKey") is False
    server, key = keyed_server
    browser.get(server.url + "/")
    wait_for(browser, "window.motionPreview && window.motionPreview.needsKey")
    form = browser.find_element(By.ID, "key-form")
    assert form.is_displayed()
    assert "needs an API key" in browser.execute_script("return window.motionPreview.lastMessage")

    def enter(text: str) -> None:
        field = browser.find_element(By.ID, "api-key")
        assert field.get_attribute("type") == "password"
        field.send_keys(text)
        browser.find_element(By.ID, "key-use").click()

    enter("msk_not-a-key-of-this-service")
    wait_for(browser, "window.motionPreview.lastMessage.includes('did not accept')")
    assert form.is_displayed()
    enter(key)
    wait_for(browser, "document.querySelector('#style-name option[value=\"elderly\"]')")
    assert not form.is_displayed()
    assert browser.execute_script("return window.motionPreview.needsKey") is False

    browser.find_element(By.ID, "content-file").send_keys(str(FIXTURE))
    wait_for(browser, "window.motionPreview.input.loaded")
    result = run_and_wait(browser)
    assert result["frames"] >= 2
    # kept for this tab only, and never in the address
    assert browser.execute_script("return sessionStorage.getItem('motion-style-api-key')") == key
    assert browser.execute_script("return localStorage.length") == 0
    assert key not in browser.current_url
    assert console_errors(browser, allow_network=True) == []  # the 401s, nothing else
