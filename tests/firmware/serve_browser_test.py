#!/usr/bin/python3
"""caphub serve's page in a real browser: Debian's headless Chromium driven by Selenium (Debian
packages chromium, chromium-driver, python3-selenium; nothing is downloaded).

The page loads from a hub running on the virtual suit, its 3D view draws the skeleton and moves
(two screenshots of it differ, and each has drawn pixels), a take is started and stopped with the
page's buttons, and a BVH download from the take list arrives and parses. Screenshots at desktop
and phone width are saved in OUT_DIR (docs/serve-desktop.png and docs/serve-phone.png come from
here). Prints the wall time.

usage: serve_browser_test.py CAPHUB SOURCE_DIR OUT_DIR
"""
import base64
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

DEADLINE_S = 60  # the most any one wait takes, on a loaded 2-core machine


def fail(message):
    print(f"FAIL: {message}", flush=True)
    raise SystemExit(1)


def wait_for(what, predicate, timeout=DEADLINE_S, interval=0.2):
    from selenium.common.exceptions import StaleElementReferenceException
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            value = predicate()
        except StaleElementReferenceException:
            value = None  # the page redrew what was found (the take list): look again
        if value:
            return value
        time.sleep(interval)
    fail(f"{what}: not within {timeout} s")


def parse_bvh(path):
    """Frames of a BVH file, checked: a hierarchy, the motion section, and every frame with one
    value per declared channel."""
    with open(path, encoding="ascii") as f:
        text = f.read()
    if not text.startswith("HIERARCHY"):
        fail(f"{path}: does not start with HIERARCHY")
    head, sep, motion = text.partition("MOTION")
    if not sep:
        fail(f"{path}: no MOTION section")
    channels = sum(int(n) for n in re.findall(r"CHANNELS\s+(\d+)", head))
    joints = len(re.findall(r"\b(?:ROOT|JOINT)\s+\S+", head))
    frames = int(re.search(r"Frames:\s*(\d+)", motion).group(1))
    lines = [l for l in motion.splitlines()[3:] if l.strip()]
    if frames <= 0 or len(lines) != frames:
        fail(f"{path}: {frames} frames declared, {len(lines)} given")
    for i, line in enumerate(lines):
        values = [float(v) for v in line.split()]
        if len(values) != channels:
            fail(f"{path}: frame {i} has {len(values)} values for {channels} channels")
    return frames, joints, channels


# Counts the pixels of the view's canvas that differ from its background (drawn on a 2D canvas
# first: works for WebGL and 2D alike).
COUNT_DRAWN = """
const src = document.querySelector('#view canvas');
const c = document.createElement('canvas');
c.width = src.width; c.height = src.height;
const g = c.getContext('2d');
g.drawImage(src, 0, 0);
const d = g.getImageData(0, 0, c.width, c.height).data;
let n = 0;
for (let i = 0; i < d.length; i += 4) {
  if (Math.abs(d[i] - 0x0f) + Math.abs(d[i + 1] - 0x17) + Math.abs(d[i + 2] - 0x2a) > 60) n++;
}
return n;
"""


def patient(what, fn, attempts=4):
    """Runs a browser command again when ChromeDriver gave up waiting for a renderer busy drawing
    (SwiftShader on a loaded two-core machine can take more than its fixed 10 s): waiting
    longer, not asserting anything about speed."""
    from selenium.common.exceptions import TimeoutException
    for i in range(attempts):
        try:
            return fn()
        except TimeoutException as e:
            print(f"{what}: the browser did not answer in time ({str(e).splitlines()[0]}); "
                  f"again ({i + 1} of {attempts})", flush=True)
            time.sleep(2)
    fail(f"{what}: the browser did not answer after {attempts} attempts")


def main():
    if len(sys.argv) != 4:
        print(__doc__)
        return 2
    caphub, source_dir, out_dir = sys.argv[1:4]
    started = time.monotonic()
    try:
        from selenium import webdriver
        from selenium.webdriver.common.by import By
        from selenium.webdriver.chrome.service import Service as ChromeService
    except ImportError as e:
        fail(f"python3-selenium is needed ({e}); toolchain/bootstrap.sh installs it")
    for tool in ("/usr/bin/chromium", "/usr/bin/chromedriver"):
        if not os.access(tool, os.X_OK):
            fail(f"{tool} is needed; toolchain/bootstrap.sh installs chromium and chromium-driver")

    os.makedirs(out_dir, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix="caphub-browser-")
    downloads = os.path.join(tmp, "downloads")
    os.makedirs(downloads)
    server = subprocess.Popen(
        [caphub, "serve", "--board", "sim-suit", "--listen", "127.0.0.1:0",
         "--recordings", os.path.join(tmp, "recordings"), "--state-dir", os.path.join(tmp, "state"),
         "--web-root", os.path.join(source_dir, "firmware", "web"),
         "--status-file", os.path.join(tmp, "status.json"), "--preview-fps", "5"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output = []
    url = []

    def read_output():
        for line in server.stdout:
            output.append(line)
            m = re.search(r"caphub serve: (http://\S+)", line)
            if m:
                url.append(m.group(1))

    reader = threading.Thread(target=read_output, daemon=True)
    reader.start()
    driver = None
    try:
        wait_for("the hub's URL", lambda: url or (server.poll() is not None and fail(
            "caphub serve ended: " + "".join(output))))
        print(f"hub: {url[0]}", flush=True)

        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                    "--window-size=1280,1000", "--use-angle=swiftshader",
                    "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"):
            options.add_argument(arg)
        options.add_experimental_option("prefs", {
            "download.default_directory": downloads,
            "download.prompt_for_download": False,
        })
        driver = webdriver.Chrome(service=ChromeService("/usr/bin/chromedriver"),
                                  options=options)
        driver.execute_cdp_cmd("Browser.setDownloadBehavior",
                               {"behavior": "allow", "downloadPath": downloads})
        driver.get(url[0])
        view = driver.find_element(By.ID, "view")
        wait_for("poses in the 3D view", lambda: int(view.get_attribute("data-poses")) >= 10)
        renderer = view.get_attribute("data-renderer")
        drawn1 = driver.execute_script(COUNT_DRAWN)
        shot1 = patient("the first screenshot", lambda: view.screenshot_as_png)
        seen = int(view.get_attribute("data-poses"))
        wait_for("more poses", lambda: int(view.get_attribute("data-poses")) >= seen + 20)
        drawn2 = driver.execute_script(COUNT_DRAWN)
        shot2 = patient("the second screenshot", lambda: view.screenshot_as_png)
        with open(os.path.join(out_dir, "view-1.png"), "wb") as f:
            f.write(shot1)
        with open(os.path.join(out_dir, "view-2.png"), "wb") as f:
            f.write(shot2)
        if drawn1 < 200 or drawn2 < 200:
            fail(f"the 3D view draws nothing ({drawn1}, {drawn2} drawn pixels)")
        if shot1 == shot2:
            fail("the 3D view does not move: two screenshots 20 poses apart are identical")
        print(f"3D view ({renderer}): {drawn1} and {drawn2} drawn pixels; the two screenshots "
              "differ", flush=True)

        # Sensors whose heading is gyro-only (no magnetometer calibration in this state folder):
        # the body calibration card names them, and the sensor table says what each waits for.
        # Read in one script so that the state and the page are of the same update.
        names, hint, cells = driver.execute_script(
            "return [state.sensors.filter((x) => x.online && x.heading === 'gyro-only')"
            ".map((x) => x.name), document.getElementById('cal-heading-hint').textContent,"
            " [...document.querySelectorAll('#sensors tbody tr')].map((r) => r.cells[6].textContent)];")
        if not names:
            fail("no sensor is gyro-only on a virtual suit without magnetometer calibration")
        if not hint.startswith(f"{len(names)} sensor") or any(n not in hint for n in names):
            fail(f"the calibration card's hint does not name the {len(names)} gyro-only sensors "
                 f"{names}: {hint!r}")
        waiting = [c for c in cells if c.startswith("gyro-only: ")]
        if len(waiting) != len(names):
            fail(f"the sensor table says what {len(waiting)} gyro-only headings wait for, "
                 f"not {len(names)}: {cells}")
        print(f"gyro-only headings named on the page: {len(names)}; e.g. {waiting[0]!r}", flush=True)

        # A heading reset from the page: the page says how it ended (done, or failed and why).
        driver.find_element(By.ID, "heading-reset").click()
        heading = driver.find_element(By.ID, "heading-status")
        said = wait_for("the heading reset's outcome on the page",
                        lambda: heading.text if (heading.text.startswith("heading reset:")
                                                 and "waiting" not in heading.text) else None)
        print(f"heading reset on the page: {said}", flush=True)

        # A take from the page's buttons.
        status = driver.find_element(By.ID, "take-status")
        driver.find_element(By.ID, "take-name").send_keys("browser")
        driver.find_element(By.ID, "take-start").click()
        wait_for("the take to start", lambda: "recording" in status.text)
        wait_for("the take to grow", lambda: re.search(r": (\d{4,}) records", status.text))
        driver.find_element(By.ID, "marker-label").send_keys("from the page")
        driver.find_element(By.ID, "marker").click()
        time.sleep(1)
        driver.find_element(By.ID, "take-stop").click()
        wait_for("the take to stop", lambda: "no take" in status.text)

        def stopped_row():
            for row in driver.find_elements(By.CSS_SELECTOR, "#takes tbody tr"):
                name = row.get_attribute("data-file") or ""
                if name.endswith("-browser.cap") and "(recording)" not in row.text:
                    return row
            return None

        row = wait_for("the take in the list", stopped_row)
        print(f"take from the page: {row.get_attribute('data-file')} ({row.text.strip()})",
              flush=True)
        if "1 markers" not in row.text:
            fail(f"the take's marker is not listed: {row.text}")
        row.find_element(By.CSS_SELECTOR, "a.dl-bvh").click()

        def downloaded():
            done = [f for f in os.listdir(downloads) if f.endswith(".bvh")]
            return done and not any(f.endswith(".crdownload") for f in os.listdir(downloads)) \
                and os.path.join(downloads, done[0])

        bvh = wait_for("the BVH download", downloaded)
        frames, joints, channels = parse_bvh(bvh)
        print(f"download from the page: {os.path.basename(bvh)}, {os.path.getsize(bvh)} bytes, "
              f"{joints} joints, {channels} channels, {frames} frames: parses", flush=True)

        # Screenshots of the whole page: desktop, then phone width.
        def page_shot(name, width, height, mobile):
            driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
                "width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile})
            time.sleep(1.5)  # layout, a few poses
            full = driver.execute_script("return document.documentElement.scrollHeight")
            shot = driver.execute_cdp_cmd("Page.captureScreenshot", {
                "format": "png", "captureBeyondViewport": True,
                "clip": {"x": 0, "y": 0, "width": width, "height": min(full, 4000), "scale": 1}})
            path = os.path.join(out_dir, name)
            with open(path, "wb") as f:
                f.write(base64.b64decode(shot["data"]))
            print(f"screenshot: {path} ({width} x {min(full, 4000)})", flush=True)

        page_shot("serve-desktop.png", 1280, 1000, False)
        page_shot("serve-phone.png", 390, 844, True)
        overflow = driver.execute_script(
            "return document.documentElement.scrollWidth > window.innerWidth + 1")
        if overflow:
            fail("at phone width the page scrolls sideways")
        errors = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        if errors:
            fail(f"the page logged errors: {errors}")
    finally:
        if driver is not None:
            driver.quit()
        server.send_signal(signal.SIGTERM)
        try:
            server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
            fail("caphub serve did not stop within 60 s of SIGTERM")
        reader.join(timeout=5)
        sys.stdout.write("".join(output[-3:]))
        shutil.rmtree(tmp, ignore_errors=True)
    if server.returncode != 0:
        fail(f"caphub serve exited with {server.returncode}")
    print(f"browser test: passed in {time.monotonic() - started:.1f} s wall time", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
