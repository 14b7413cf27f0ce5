"""Drives the ecmxfd dashboard in a real browser (headless Chromium through
Selenium and chromium-driver, or with `--browser firefox` headless Firefox
ESR through geckodriver) for tests/tests/web.rs, and prints what the page
showed as one JSON line. The Rust test compares it with what ecmxfctl and
the gRPC API say.

Usage: web_check.py [--browser chromium|firefox] MODE URL ARGS...

Modes:
  pages URL SHOTS_DIR            every view at 1280x800 and 768x1024: the
                                 screenshots, the console, the slaves table,
                                 the overview's summary, text that overflows
  unplug URL CTL...              the overview while CTL... unplugs a slave:
                                 how long until the page shows it lost
  plot URL VAR SECONDS           a plot of VAR for SECONDS, then its CSV
  sdo URL SLAVE INDEX SUB        an SDO read from the slave page
  writes URL TOKEN SLAVE INDEX SUB OUTPUT VALUE
                                 an anonymous SDO write (refused, with its
                                 message), then a login and an output write
  load URL SESSIONS SECONDS      for ecmxfd-web-bench: SESSIONS plots pages'
                                 streams, read for SECONDS (no browser)
"""

import json
import os
import shutil
import subprocess
import sys
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.firefox.service import Service as FirefoxService

VIEWS = ["overview", "topology", "slaves", "slave/1", "plots", "events", "axes", "config"]
SIZES = [(1280, 800), (768, 1024)]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# The browser the modes drive: main() sets it from --browser.
BROWSER = "chromium"


def browser(width=1280, height=800):
    driver = firefox(width, height) if BROWSER == "firefox" else chromium(width, height)
    # The window's inner size is what a screen of that size shows.
    driver.set_window_size(width, height)
    inner = driver.execute_script("return [window.innerWidth, window.innerHeight]")
    driver.set_window_size(width + (width - inner[0]), height + (height - inner[1]))
    return driver


def chromium(width, height):
    options = webdriver.ChromeOptions()
    options.binary_location = os.environ.get("ECMXF_CHROMIUM", shutil.which("chromium") or "/usr/bin/chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                f"--window-size={width},{height}", "--hide-scrollbars"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver_path = os.environ.get("ECMXF_CHROMEDRIVER", shutil.which("chromedriver") or "/usr/bin/chromedriver")
    return webdriver.Chrome(service=Service(driver_path), options=options)


# Firefox's driver has no browser log (get_log): its console errors come
# over WebDriver BiDi instead, where the session subscribes before the
# first page loads, so nothing a page logs while it loads is missed.
PROBE = "ecmxf-console-probe"


def firefox(width, height):
    options = webdriver.FirefoxOptions()
    options.binary_location = os.environ.get(
        "ECMXF_FIREFOX", shutil.which("firefox-esr") or shutil.which("firefox") or "/usr/bin/firefox-esr")
    for arg in ("-headless", f"--width={width}", f"--height={height}"):
        options.add_argument(arg)
    options.enable_bidi = True
    driver_path = os.environ.get("ECMXF_GECKODRIVER", os.path.join(REPO, "target/tools/bin/geckodriver"))
    driver = webdriver.Firefox(service=FirefoxService(driver_path), options=options)
    errors = driver.ecmxf_errors = []
    try:
        # What the console shows as an error: uncaught exceptions, CSP and
        # nosniff refusals (BiDi's "javascript" entries) and console.error.
        driver.script.add_javascript_error_handler(lambda e: errors.append(e.text))
        driver.script.add_console_message_handler(
            lambda e: errors.append(e.text) if e.level == "error" else None)
        # Chromium logs an HTTP error answer to any request as an error;
        # Firefox shows it only in its network panel: said here in
        # Chromium's words, so the same `expected` filters apply.
        driver.network.add_event_handler("response_started", lambda e: errors.append(
            f"{e['request']['url']} - Failed to load resource: the server responded with a status of "
            f"{e['response']['status']} ({e['response'].get('statusText', '')})")
            if e["response"]["status"] >= 400 else None)
        # A check that would find nothing because no entry ever arrives
        # (BiDi off, a handler the driver ignores) fails here instead.
        driver.execute_script(f"console.error('{PROBE}'); setTimeout(() => {{ throw new Error('{PROBE}'); }});")
        probes = lambda: [e for e in errors if PROBE in e]  # noqa: E731
        wait_for(driver, lambda: len(probes()) == 2, timeout=5, what="a console error and an exception over BiDi")
        for e in probes():
            errors.remove(e)
    except BaseException:
        driver.quit()
        raise
    return driver


def wait_for(driver, condition, timeout=10.0, what="the page"):
    end = time.time() + timeout
    while True:
        try:
            got = condition()
            if got:
                return got
        except Exception:  # noqa: BLE001 - the element may not be there yet
            pass
        if time.time() > end:
            raise TimeoutError(f"{what} did not appear within {timeout} s")
        time.sleep(0.05)


def text(driver, css):
    found = driver.find_elements(By.CSS_SELECTOR, css)
    return found[0].text if found else None


def console_errors(driver, expected=()):
    """The console's errors since the last call, but for `expected` ones:
    Chromium logs every HTTP error answer to a fetch as an error, a refusal
    the test provokes too."""
    if BROWSER == "firefox":
        # Entries arrive over BiDi a moment after the page logs them, on
        # another thread: taken one by one, none is lost in between.
        time.sleep(0.2)
        errors = driver.ecmxf_errors
        found = [errors.pop(0) for _ in range(len(errors))]
    else:
        found = [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    return [m for m in found if not any(x in m for x in expected)]


# Read in one script: the live summary redraws four times a second, and
# what is read must be one redraw's.
SUMMARY = """
const t = (id) => { const e = document.getElementById(id); return e ? e.textContent.trim() : null; };
return {
  healthy: document.getElementById('summary').dataset.healthy,
  health: t('summary-health'), state: t('summary-state'), slaves: t('summary-slaves'), lost: t('summary-lost'),
  problems: Array.from(document.querySelectorAll('#problems li'), (li) => li.textContent.trim()),
  link: t('chart-exchanges-now'),
};
"""


def summary(driver):
    return driver.execute_script(SUMMARY)


# Text cut off or running out of its box: an element whose content is wider
# than its box where the box hides it, or any element past the page's right
# edge (the page itself must not scroll sideways; wide tables scroll inside
# their own container).
OVERFLOW = """
const out = [];
const width = document.documentElement.clientWidth;
for (const el of document.querySelectorAll('body *')) {
  const r = el.getBoundingClientRect();
  if (r.width === 0 || r.height === 0) continue;
  const style = getComputedStyle(el);
  if (style.visibility === 'hidden') continue;
  let inScroller = false;
  for (let p = el.parentElement; p; p = p.parentElement) {
    const o = getComputedStyle(p).overflowX;
    if (o === 'auto' || o === 'scroll') { inScroller = true; break; }
  }
  if (!inScroller && r.right > width + 1 && el.children.length === 0 && el.textContent.trim()) {
    out.push(`past the right edge: <${el.tagName.toLowerCase()}> "${el.textContent.trim().slice(0, 40)}"`);
  }
  const clips = style.overflowX === 'hidden' || style.overflow === 'hidden';
  if (clips && el.scrollWidth > el.clientWidth + 1 && style.textOverflow !== 'ellipsis' && !el.title) {
    out.push(`cut off: <${el.tagName.toLowerCase()}> "${el.textContent.trim().slice(0, 40)}"`);
  }
}
return out;
"""


def view_ready(driver, view):
    root = "view-" + view.split("/")[0]
    wait_for(driver, lambda: driver.find_element(By.ID, root), what=f"#{root}")
    ready = {
        "overview": lambda: text(driver, "#summary-slaves"),
        "topology": lambda: driver.find_elements(By.CSS_SELECTOR, "#topology g.slave"),
        "slaves": lambda: driver.find_elements(By.CSS_SELECTOR, "#slaves-table tr[data-position]"),
        "slave": lambda: driver.find_elements(By.CSS_SELECTOR, "#entries-table tr[data-entry]"),
        "plots": lambda: driver.find_elements(By.CSS_SELECTOR, "input.plot-var"),
        "events": lambda: driver.find_elements(By.ID, "events-table"),
        "axes": lambda: driver.find_elements(By.ID, "view-axes"),
        "config": lambda: driver.find_elements(By.ID, "download-toml"),
    }[view.split("/")[0]]
    wait_for(driver, ready, what=f"the {view} view's content")
    # Let live data and charts draw once more.
    time.sleep(0.6)


def pages(url, shots):
    os.makedirs(shots, exist_ok=True)
    out = {"console": [], "overflow": {}, "shots": []}
    for width, height in SIZES:
        driver = browser(width, height)
        try:
            for view in VIEWS:
                driver.get(f"{url}#/{view}")
                view_ready(driver, view)
                name = f"{view.replace('/', '-')}-{width}x{height}.png"
                driver.save_screenshot(os.path.join(shots, name))
                out["shots"].append(name)
                over = driver.execute_script(OVERFLOW)
                if over:
                    out["overflow"][name] = over[:10]
                if view == "overview" and width == 1280:
                    wait_for(driver, lambda: text(driver, "#summary-slaves"))
                    out["summary"] = summary(driver)
                    # The charts' past, as the page fetched it.
                    out["trend"] = driver.execute_async_script(
                        "const done = arguments[0];"
                        "fetch('/api/trend').then((r) => r.json()).then((d) => done(d.trend), () => done(null));")
                if view == "slaves" and width == 1280:
                    rows = []
                    for tr in driver.find_elements(By.CSS_SELECTOR, "#slaves-table tr[data-position]"):
                        cell = lambda f: tr.find_element(By.CSS_SELECTOR, f'[data-field="{f}"]')  # noqa: E731
                        rows.append({
                            "position": int(tr.get_attribute("data-position")),
                            "name": cell("name").text,
                            "state": cell("state").text,
                            "vendor_id": int(cell("vendor_id").get_attribute("data-value")),
                            "product_code": int(cell("product_code").get_attribute("data-value")),
                            "revision": int(cell("revision").get_attribute("data-value")),
                            "al_status_code": int(cell("al_status").get_attribute("data-value")),
                            "al_status": cell("al_status").text,
                            "errors": int(cell("errors").get_attribute("data-value") or -1),
                        })
                    out["slaves"] = rows
            out["console"] += console_errors(driver)
        finally:
            driver.quit()
    return out


def unplug(url, ctl):
    driver = browser()
    try:
        driver.get(f"{url}#/overview")
        before = wait_for(driver, lambda: summary(driver) if text(driver, "#summary-slaves") else None)
        # A loaded host can stall the engine for a moment (the summary then
        # says so, for a while): the unplug starts from a settled network.
        settle = time.time() + 15
        while time.time() < settle and any(p.startswith("process data stalled") for p in before["problems"]):
            time.sleep(0.25)
            before = summary(driver)
        subprocess.run(ctl, check=True, capture_output=True)
        start = time.time()
        wait_for(driver, lambda: "2" in (text(driver, "#summary-lost") or ""), timeout=5, what="the lost slave")
        elapsed = time.time() - start
        # The rest of the summary follows within the same message.
        time.sleep(0.3)
        after = summary(driver)
        driver.get(f"{url}#/topology")
        lost = wait_for(driver, lambda: [
            int(g.get_attribute("data-position"))
            for g in driver.find_elements(By.CSS_SELECTOR, '#topology g.slave[data-lost="true"]')
        ], what="a lost slave on the topology")
        # The lost slave's own page says so, under the name it had.
        driver.get(f"{url}#/slave/{lost[0]}")
        lost_page = wait_for(driver, lambda: text(driver, "#slave-lost"), what="the lost slave's page")
        driver.get(f"{url}#/slaves")
        matches = wait_for(driver, lambda: text(driver, "#slaves-matches"), what="the slaves view")
        return {"before": before, "after": after, "elapsed_ms": elapsed * 1000, "topology_lost": lost,
                "lost_page": lost_page, "slaves_matches": matches, "console": console_errors(driver)}
    finally:
        driver.quit()


def plot(url, var, seconds):
    driver = browser()
    try:
        driver.get(f"{url}#/plots")
        box = wait_for(driver, lambda: driver.find_element(By.CSS_SELECTOR, f'input.plot-var[value="{var}"]'),
                       what=f"the checkbox of {var}")
        driver.execute_script("arguments[0].scrollIntoView()", box)
        box.click()
        driver.find_element(By.ID, "plot-start").click()
        wait_for(driver, lambda: driver.execute_script("return window.ecmxfPlotPoints()") > 0, what="the first points")
        first = driver.execute_script("return window.ecmxfPlotPoints()")
        time.sleep(seconds)
        last = driver.execute_script("return window.ecmxfPlotPoints()")
        driver.find_element(By.ID, "plot-pause").click()
        csv = driver.execute_script("return window.ecmxfPlotCsv()")
        return {"first": first, "last": last, "csv": csv, "console": console_errors(driver)}
    finally:
        driver.quit()


def sdo_read(driver, url, slave, index, sub):
    driver.get(f"{url}#/slave/{slave}")
    wait_for(driver, lambda: driver.find_element(By.ID, "sdo-read"), what="the SDO form")
    for field, value in (("sdo-index", index), ("sdo-sub", sub)):
        el = driver.find_element(By.ID, field)
        el.clear()
        el.send_keys(value)
    driver.execute_script("document.getElementById('sdo-result').textContent = ''")
    driver.find_element(By.ID, "sdo-read").click()
    return wait_for(driver, lambda: driver.find_element(By.ID, "sdo-result").text, what="the SDO result")


def sdo(url, slave, index, sub):
    driver = browser()
    try:
        value = sdo_read(driver, url, slave, index, sub)
        return {"value": value, "type": text(driver, "#sdo-type"), "console": console_errors(driver)}
    finally:
        driver.quit()


def message(driver):
    el = driver.find_element(By.ID, "message")
    return {"text": el.text, "class": el.get_attribute("class"), "visible": el.is_displayed()}


def writes(url, token, slave, index, sub, output, value):
    driver = browser()
    try:
        out = {"before": sdo_read(driver, url, slave, index, sub)}
        el = driver.find_element(By.ID, "sdo-value")
        el.clear()
        el.send_keys("4321")
        driver.execute_script("document.getElementById('message').textContent = ''")
        driver.find_element(By.ID, "sdo-write").click()
        wait_for(driver, lambda: driver.find_element(By.ID, "message").text, what="the refusal")
        out["refused"] = message(driver)
        refusal = f"/api/slaves/{slave}/sdo/{index}/{sub} - Failed to load resource: the server responded with a status of 403"
        out["console"] = console_errors(driver, [refusal])
        out["after_refusal"] = sdo_read(driver, url, slave, index, sub)
        # Log in as the operator.
        wait_for(driver, lambda: driver.find_element(By.ID, "login-token").is_displayed(), what="the login form")
        driver.find_element(By.ID, "login-token").send_keys(token)
        driver.find_element(By.ID, "login-button").click()
        wait_for(driver, lambda: "operator" in driver.find_element(By.ID, "whoami").text, what="the operator")
        out["whoami"] = driver.find_element(By.ID, "whoami").text
        out_slave = output.split(".")[0]
        driver.get(f"{url}#/slave/{out_slave}")
        box = wait_for(driver, lambda: driver.find_element(By.CSS_SELECTOR, f'input.output-value[data-entry="{output}"]'),
                       what=f"the input of {output}")
        box.clear()
        box.send_keys(value)
        driver.execute_script("document.getElementById('message').textContent = ''")
        driver.find_element(By.CSS_SELECTOR, f'button.output-write[data-entry="{output}"]').click()
        wait_for(driver, lambda: driver.find_element(By.ID, "message").text, what="the write's answer")
        out["written"] = message(driver)
        out["console"] += console_errors(driver)
        return out
    finally:
        driver.quit()


def load(url, sessions, seconds):
    """SESSIONS browsers on the plots page, as the daemon sees them: each
    holds the live feed and a plot of 8 inputs open (what the page opens),
    read as they come. Prints "subscribed" once all are open, then after
    SECONDS the events they received."""
    import http.client
    import threading
    from urllib.parse import quote, urlparse

    where = urlparse(url)
    conn = http.client.HTTPConnection(where.hostname, where.port, timeout=10)
    conn.request("GET", "/api/entries")
    entries = json.loads(conn.getresponse().read())["entries"]
    inputs = [e["name"] for e in entries if e["direction"] == "input"][:8]
    paths = ["/api/live", "/api/plot?vars=" + quote(",".join(inputs))]
    counts = []
    # A stream that cannot open breaks the barrier: the load fails, it
    # never hangs.
    opened = threading.Barrier(int(sessions) * len(paths) + 1, timeout=10)
    stop = time.time() + float(seconds)

    def read(path, slot):
        try:
            c = http.client.HTTPConnection(where.hostname, where.port, timeout=10)
            c.request("GET", path, headers={"Accept": "text/event-stream"})
            r = c.getresponse()
            if r.status != 200:
                raise RuntimeError(f"{path}: {r.status} {r.read()[:200]!r}")
        except Exception:
            opened.abort()
            raise
        opened.wait()
        while time.time() < stop:
            line = r.readline()
            if not line:
                break
            if line.startswith(b"data:"):
                counts[slot] += 1
        c.close()

    threads = []
    for i in range(int(sessions)):
        for path in paths:
            counts.append(0)
            t = threading.Thread(target=read, args=(path, len(counts) - 1), daemon=True)
            t.start()
            threads.append(t)
    opened.wait()
    print("subscribed", flush=True)
    for t in threads:
        t.join(float(seconds) + 5)
    return {"streams": len(counts), "messages": sum(counts), "per_second": sum(counts) / float(seconds),
            "variables": len(inputs)}


def main():
    global BROWSER
    argv = sys.argv[1:]
    if argv[:1] == ["--browser"]:
        BROWSER, argv = argv[1], argv[2:]
        if BROWSER not in ("chromium", "firefox"):
            raise SystemExit(f"unknown browser {BROWSER} (chromium or firefox)")
    mode, url = argv[0], argv[1]
    args = argv[2:]
    if mode == "pages":
        result = pages(url, args[0])
    elif mode == "unplug":
        result = unplug(url, args)
    elif mode == "plot":
        result = plot(url, args[0], float(args[1]))
    elif mode == "sdo":
        result = sdo(url, *args)
    elif mode == "writes":
        result = writes(url, *args)
    elif mode == "load":
        result = load(url, *args)
    else:
        raise SystemExit(f"unknown mode {mode}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
