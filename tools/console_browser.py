#!/usr/bin/env python3
"""Drives headless Chromium through the DevTools protocol against the operator console.

Modes:
  not-running URL             the page must say the stack is not running; START RIDE disabled
                              and saying why, STOP enabled
  live-stop   URL OUTDIR [PID]  50 updates in order and live values, a screenshot, START RIDE
                              disabled (the ride started at launch), the STOP button (a real
                              mouse click) e-stops the stack: motion-core latches, the drives
                              quick-stop, the trip log names the operator and is in time order
                              (newest first), STOP stays enabled; with PID (the `crs sim`
                              serving the console): SIGINT to it, then the page says
                              DISCONNECTED and every badge is grey ("unknown")
  start-ride  URL OUTDIR      `crs sim --start-from-console`: START RIDE enabled once every
                              pre-ride check passes, a real click starts the ride (the
                              platform moves), START disabled while riding, STOP stops it
  report      DIR             a run report (DIR/index.html, served over HTTP): named summary
                              fields with units, completed / stopped in words, events in words
                              (no state codes, no repeated state), the tracking-error plot in
                              mm, the ride-path plot linked, no text of any plot on its data
                              lines (legends off the data), every link and image resolves
Prints one line per check; exits 1 on the first failure.
"""
import base64
import functools
import http.server
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

import websocket  # websocket-client


def fail(msg):
    print(f"CONSOLE-BROWSER: FAIL: {msg}", flush=True)
    sys.exit(1)


class Browser:
    def __init__(self, url):
        exe = shutil.which("chromium") or shutil.which("chromium-browser")
        if not exe:
            fail("chromium not installed")
        self.profile = tempfile.mkdtemp(prefix="crs-console-chromium-")
        self.proc = subprocess.Popen(
            [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
             "--no-first-run", "--remote-debugging-port=0", f"--user-data-dir={self.profile}",
             "--window-size=1500,1050", url],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = os.path.join(self.profile, "DevToolsActivePort")
        t0 = time.time()
        while not os.path.exists(port_file) or os.path.getsize(port_file) == 0:
            if time.time() - t0 > 30 or self.proc.poll() is not None:
                fail("chromium did not start its DevTools endpoint")
            time.sleep(0.1)
        port = open(port_file).read().split()[0]
        ws_url = None
        while ws_url is None:
            targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
            pages = [t for t in targets if t.get("type") == "page"]
            if pages:
                ws_url = pages[0]["webSocketDebuggerUrl"]
            elif time.time() - t0 > 30:
                fail("no page target in chromium")
            else:
                time.sleep(0.1)
        self.ws = websocket.create_connection(ws_url, timeout=30)
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        my = self.next_id
        self.ws.send(json.dumps({"id": my, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my:
                if "error" in msg:
                    fail(f"{method}: {msg['error']}")
                return msg["result"]

    def js(self, expr, wait_promise=False):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True, awaitPromise=wait_promise)
        if "exceptionDetails" in r:
            fail(f"page script error in {expr!r}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def text(self, elem_id):
        return self.js(f"(document.getElementById({elem_id!r}) || {{}}).textContent || ''")

    def wait(self, what, cond, timeout_s):
        t0 = time.time()
        while time.time() - t0 < timeout_s:
            v = cond()
            if v:
                return v
            time.sleep(0.1)
        fail(f"timed out after {timeout_s} s waiting for {what}")

    def screenshot(self, path):
        # The whole page, not just the window.
        h = self.js("document.documentElement.scrollHeight")
        self.call("Emulation.setDeviceMetricsOverride", width=1500, height=int(h), deviceScaleFactor=1, mobile=False)
        time.sleep(0.2)
        data = self.call("Page.captureScreenshot", format="png")["data"]
        with open(path, "wb") as f:
            f.write(base64.b64decode(data))
        print(f"  screenshot {path}", flush=True)

    def click(self, elem_id):
        box = self.js(f"(() => {{ const r = document.getElementById({elem_id!r}).getBoundingClientRect();"
                       " return [r.x + r.width / 2, r.y + r.height / 2]; })()")
        for t in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=t, x=box[0], y=box[1], button="left", clickCount=1)

    def close(self):
        try:
            self.ws.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
            shutil.rmtree(self.profile, ignore_errors=True)


def checks(b):
    """The pre-ride checks as the page shows them: [(name, ok, seen)]."""
    return b.js("""[...document.querySelectorAll('#ride-checks tr[data-ok]')].map(
        (r) => [r.cells[0].textContent, r.dataset.ok === 'true', r.cells[2].textContent])""") or []


def check_start_disabled(b, when, failing):
    """START RIDE is disabled and the check `failing` is shown failing (with what was seen)."""
    b.wait("the pre-ride checks on the page", lambda: len(checks(b)) == 5, 30)
    if not b.js("document.getElementById('start-btn').disabled"):
        fail(f"{when}: START RIDE is enabled; checks {checks(b)}")
    bad = [c for c in checks(b) if not c[1]]
    if not any(c[0] == failing for c in bad):
        fail(f"{when}: the check {failing!r} does not fail on the page: {checks(b)}")
    print(f"  {when}: START RIDE disabled; failing: " + "; ".join(f"{n} ({seen})" for n, _, seen in bad)[:300], flush=True)


def badges_unknown_after(b, pid):
    """SIGINT to the process serving the console: the page must say so and show no state."""
    os.kill(pid, signal.SIGINT)
    b.wait("the page to notice the console server is gone",
           lambda: b.text("stack-state") == "CONSOLE DISCONNECTED", 60)
    mon = b.js("[document.getElementById('monitor-state').textContent, document.getElementById('monitor-state').className]")
    motion, bus = b.text("motion-state"), b.text("bus-state")
    if mon != ["unknown", "badge idle"]:
        fail(f"disconnected, the monitor badge says {mon}")
    if motion != "unknown" or bus != "unknown":
        fail(f"disconnected, motion {motion!r}, drives {bus!r}")
    if not b.js("document.getElementById('start-btn').disabled"):
        fail("disconnected, START RIDE is enabled")
    print(f"  console server gone: {b.text('stack-state')!r}; monitor badge {mon[0]!r} (grey), motion {motion!r}, "
          f"drives {bus!r}, START RIDE disabled", flush=True)


def trip_times(b):
    return b.js("""[...document.querySelectorAll('#trips tr')].slice(1).map((r) => parseFloat(r.cells[0].textContent))""") or []


def not_running(url):
    b = Browser(url)
    try:
        state = b.wait("the page's stack state", lambda: b.text("stack-state") not in ("", "connecting…") and b.text("stack-state"), 30)
        if state != "STACK NOT RUNNING":
            fail(f"without a stack the page says {state!r}")
        banner = b.text("banner")
        if "not running" not in banner:
            fail(f"banner says {banner!r}")
        print(f"  no stack: page says {state!r}; banner {banner[:60]!r}…", flush=True)
        check_start_disabled(b, "no stack", "stack running")
        if b.js("document.getElementById('stop-btn').disabled"):
            fail("STOP is disabled")
        print("  STOP enabled", flush=True)
    finally:
        b.close()


def live_stop(url, outdir, pid=None):
    b = Browser(url)
    try:
        b.wait("the stack running with setpoints and plant states",
               lambda: b.text("stack-state") == "stack running" and b.text("setpoint-seq") not in ("", "0")
               and b.text("act-pos") not in ("", "–"), 60)
        keys = ("setpoint-seq", "ref-pos", "act-pos", "loop-cycles", "prog-text")
        # Updates keep arriving, each a newer snapshot of the console's poller: 50 of them, in
        # order. Counted, not timed: the update rate on this shared host is a benchmark figure
        # (tools/console-load.sh, benches/RESULTS.md "Operator console: load"), printed here only.
        (u0, s0, back0), t0 = b.js("window.consoleProgress()"), time.time()
        b.wait("50 more updates on the page", lambda: b.js("window.consoleProgress()")[0] >= u0 + 50, 60)
        (u1, s1, back1), t1 = b.js("window.consoleProgress()"), time.time()
        print(f"  live: {u1 - u0} updates received, snapshots #{s0} -> #{s1} "
              f"({(s1 - s0) - (u1 - u0)} superseded before the page read them); "
              f"{(u1 - u0) / (t1 - t0):.1f} updates/s on this host (not asserted)", flush=True)
        if back1 != back0:
            fail(f"{back1 - back0} updates older than the one before them")
        if not s1 - s0 >= u1 - u0:
            fail(f"{u1 - u0} updates but the snapshot number advanced only {s1 - s0}")
        # Live values: two reads 0.3 s apart while the platform moves (it rests at waypoints).
        seen = {}
        def moving():
            v0 = {k: b.text(k) for k in keys}
            time.sleep(0.3)
            v1 = {k: b.text(k) for k in keys}
            seen["v"] = (v0, v1)
            return v0["ref-pos"] != v1["ref-pos"] and v0["act-pos"] != v1["act-pos"]
        b.wait("the reference and the measured pose to move", moving, 60)
        v0, v1 = seen["v"]
        print(f"  setpoint # {v0['setpoint-seq']} -> {v1['setpoint-seq']}; "
              f"reference {v0['ref-pos']} -> {v1['ref-pos']}; measured {v0['act-pos']} -> {v1['act-pos']}; "
              f"progress {v1['prog-text']!r}", flush=True)
        if not int(v1["setpoint-seq"]) > int(v0["setpoint-seq"]):
            fail("the setpoint number did not advance")
        if b.text("monitor-state") != "armed":
            fail(f"monitor state {b.text('monitor-state')!r} before the stop")
        b.screenshot(os.path.join(outdir, "screenshot.png"))
        # The ride started at launch: no control socket for the console, START disabled.
        check_start_disabled(b, "ride started at launch", "motion-core idle and holding")
        # The operator presses STOP (a real mouse click on the button).
        b.click("stop-btn")
        if b.js("document.getElementById('stop-btn').disabled"):
            fail("STOP disabled after a press")
        b.wait("motion-core to latch the e-stop", lambda: "E-STOPPED" in b.text("motion-state"), 15)
        b.wait("drive-io to quick-stop the drives", lambda: b.text("bus-state") == "EStop", 15)
        b.wait("the trip log to name the operator's stop",
               lambda: "stop requested by an operator" in b.js("document.getElementById('trips').textContent"), 15)
        # Nothing moves any more: the reference is frozen.
        r0 = b.text("ref-pos")
        time.sleep(1.0)
        if b.text("ref-pos") != r0:
            fail("the reference still changes after the stop")
        drives = b.js("document.getElementById('drives').textContent")
        print(f"  stop: motion {b.text('motion-state')!r}, drives {b.text('bus-state')!r}, "
              f"monitor {b.text('monitor-state')!r}, quick stop in drive table: {'quick stop active' in drives}", flush=True)
        times = trip_times(b)
        if len(times) < 1 or any(a < c for a, c in zip(times, times[1:])):
            fail(f"trip log not newest first: t = {times}")
        api = json.load(urllib.request.urlopen(url.rstrip("/") + "/api/trips"))
        api_t = [e["t_s"] for e in api]
        if any(a > c for a, c in zip(api_t, api_t[1:])):
            fail(f"/api/trips not in time order: {api_t}")
        if not any(e["source"] == "operator" and e["kind"] == "E-STOP" for e in api):
            fail(f"/api/trips without the operator's e-stop: {api}")
        print(f"  trip log: {len(times)} rows on the page, newest first (t {times[:4]}…); /api/trips {len(api)} entries "
              "oldest first, the operator's e-stop among them", flush=True)
        if not b.js("!document.getElementById('stop-btn').disabled"):
            fail("STOP disabled after the stop")
        b.screenshot(os.path.join(outdir, "screenshot-stopped.png"))
        if pid is not None:
            badges_unknown_after(b, pid)
            b.screenshot(os.path.join(outdir, "screenshot-disconnected.png"))
    finally:
        b.close()


def start_ride(url, outdir):
    b = Browser(url)
    try:
        b.wait("the stack running", lambda: b.text("stack-state") == "stack running", 90)
        # Every pre-ride check passes once the drives are up, the monitor is armed and
        # motion-core idles at home: only then is the button enabled.
        seen = {}
        def all_pass():
            seen["c"] = checks(b)
            return len(seen["c"]) == 5 and all(c[1] for c in seen["c"])
        t0 = time.time()
        while not all_pass():
            if time.time() - t0 > 120:
                fail(f"the pre-ride checks never all passed in 120 s: {seen['c']}")
            time.sleep(0.2)
        b.wait("START RIDE enabled", lambda: not b.js("document.getElementById('start-btn').disabled"), 10)
        print("  pre-ride checks: " + "; ".join(f"{n}: {seen}" for n, _, seen in checks(b)), flush=True)
        print(f"  START RIDE enabled ({b.text('ride-loaded')})", flush=True)
        b.screenshot(os.path.join(outdir, "screenshot-ready.png"))
        seq0 = int(b.text("setpoint-seq") or 0)
        r0 = b.text("ref-pos")
        b.click("start-btn")
        b.wait("the ride to start", lambda: "ride started" in b.text("ride-result")
               or "NOT" in b.text("ride-result") or "refused" in b.text("ride-result"), 30)
        res = b.text("ride-result")
        if "ride started" not in res:
            fail(f"the start button's request: {res!r}")
        print(f"  clicked START RIDE: {res!r}", flush=True)
        b.wait("the reference to move", lambda: b.text("ref-pos") != r0, 30)
        b.wait("motion-core riding", lambda: "riding" in b.text("ride-control"), 15)
        check_start_disabled(b, "riding", "motion-core idle and holding")
        print(f"  riding: setpoint #{seq0} -> #{b.text('setpoint-seq')}, reference {r0} -> {b.text('ref-pos')}", flush=True)
        if b.js("document.getElementById('stop-btn').disabled"):
            fail("STOP disabled while riding")
        b.click("stop-btn")
        b.wait("motion-core to latch the e-stop", lambda: "E-STOPPED" in b.text("motion-state"), 15)
        check_start_disabled(b, "after STOP", "no latched trip")
        b.screenshot(os.path.join(outdir, "screenshot-started-stopped.png"))
    finally:
        b.close()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *a):
        pass


def report(outdir):
    """The run report of `crs sim` in a browser (served over HTTP so the page can fetch its
    own plots)."""
    summary = json.load(open(os.path.join(outdir, "summary.json")))
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=outdir))
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{srv.server_address[1]}/"
    b = Browser(base + "index.html")
    try:
        b.wait("the report", lambda: b.js("document.readyState") == "complete"
               and b.js("document.querySelectorAll('img').length > 0")
               and b.js("[...document.images].every((i) => i.complete)"), 30)
        # 1. The summary: named fields (words, not JSON keys) with their units.
        rows = b.js("""[...document.querySelectorAll('#summary-table tr[data-field]')].map(
            (r) => [r.dataset.field, r.cells[0].textContent, r.cells[1].textContent, r.cells[2].textContent])""")
        if len(rows) < 20:
            fail(f"summary table has {len(rows)} fields")
        unit_of = {"_mm": "mm", "_deg": "°", "_n": "N", "_us": "µs", "_s": "s"}
        with_unit = 0
        for field, name, value, unit in rows:
            if "_" in name:
                fail(f"summary field {field!r} shown by its key: {name!r}")
            want = next((u for suf, u in unit_of.items() if field.endswith(suf)), None)
            if want is not None:
                if unit != want:
                    fail(f"summary field {name!r} ({field}) has unit {unit!r}, not {want!r}")
                with_unit += 1
            if re.fullmatch(r"\{.*\}|\[.*\]", value.strip()):
                fail(f"summary field {name!r} is a JSON blob: {value[:80]!r}")
        print(f"  summary: {len(rows)} named fields, {with_unit} with their unit (mm, °, N, µs, s); first "
              f"{[r[1] for r in rows[:4]]}", flush=True)
        # 2. Completed or stopped, in words, as summary.json says.
        verdict = b.js("document.querySelector('.verdict').textContent")
        if summary["completed"]:
            if not verdict.startswith("Completed"):
                fail(f"completed run, verdict {verdict!r}")
        else:
            if not verdict.startswith("STOPPED") or (summary.get("stopped_by") and summary["stopped_by"] not in verdict):
                fail(f"stopped run ({summary.get('stopped_by')}), verdict {verdict!r}")
        print(f"  verdict: {verdict!r} (summary.json completed={summary['completed']})", flush=True)
        # 3. Events in words, state changes only.
        ev = b.js("""[...document.querySelectorAll('#events-table tr')].slice(1).map((r) => [...r.cells].map((c) => c.textContent))""")
        ev = [e for e in ev if len(e) == 3]
        for t, src, what in ev:
            if re.search(r"\bstate \d", what) or re.fullmatch(r"[\d\s/]+", what):
                fail(f"an event as a code: {src}: {what!r}")
        last = {}
        for t, src, what in ev:
            if last.get(src) == what and not what.startswith(("E-STOP", "fault", "reset")):
                fail(f"{src} repeats {what!r} (state changes only)")
            last[src] = what
        times = [float(e[0]) for e in ev]
        if any(a > c for a, c in zip(times, times[1:])):
            fail("events not in time order")
        print(f"  events: {len(ev)} in words, in time order, no repeated state; e.g. "
              f"{[f'{s}: {w}' for _, s, w in ev[:3]]}", flush=True)
        # 4. Every image and link resolves.
        imgs = b.js("[...document.images].map((i) => [i.getAttribute('src'), i.naturalWidth])")
        for src, w in imgs:
            if not w:
                fail(f"image {src} did not load")
        links = b.js("[...document.querySelectorAll('a[href]')].map((a) => a.getAttribute('href'))")
        for href in links:
            try:
                urllib.request.urlopen(base + href).read(1)
            except Exception as e:  # noqa: BLE001 - any failure is the finding
                fail(f"link {href} does not resolve: {e}")
        if "tracking.svg" not in [s for s, _ in imgs]:
            fail("no tracking-error plot")
        if "path.svg" not in links:
            fail("the ride-path plot is not linked")
        print(f"  {len(imgs)} images loaded, {len(links)} links resolve (path.svg linked)", flush=True)
        # 5. The tracking-error plot is in mm, and no plot writes on its data.
        for src, _ in imgs:
            n_lines, hits, n_text, axes = b.js(f"""(async () => {{
                const txt = await (await fetch({json.dumps(src)})).text();
                const host = document.createElement('div');
                host.style.cssText = 'position:absolute;left:0;top:0;visibility:hidden';
                host.innerHTML = txt;
                document.body.appendChild(host);
                const svg = host.querySelector('svg');
                const data = [...svg.querySelectorAll('polyline')].filter(
                    (p) => p.getAttribute('points').trim().split(/\s+/).length >= 10).map((p) => p.getBBox());
                const texts = [...svg.querySelectorAll('text')];
                const hits = [];
                for (const t of texts) {{
                    const a = t.getBBox();
                    for (const d of data) {{
                        if (a.x < d.x + d.width && d.x < a.x + a.width && a.y < d.y + d.height && d.y < a.y + a.height) {{
                            hits.push(t.textContent.trim()); break;
                        }}
                    }}
                }}
                const axes = texts.map((t) => t.textContent.trim()).filter((s) => s === 'mm' || s === '°');
                host.remove();
                return [data.length, hits, texts.length, axes];
            }})()""", wait_promise=True) if src.endswith(".svg") else (0, [], 0, [])
            if src == "tracking.svg":
                if n_lines < 4 or "mm" not in axes:
                    fail(f"tracking.svg: {n_lines} data lines, axes {axes}")
            if src == "events.svg":
                # The events plot labels its markers on purpose.
                print(f"  events.svg: {n_text} texts (event labels next to their markers, not checked)", flush=True)
                continue
            if hits:
                fail(f"{src}: text on the data lines: {hits[:5]}")
            print(f"  {src}: {n_lines} data lines, {n_text} texts, none on the data"
                  + (f"; axes in {sorted(set(axes))}" if src == "tracking.svg" else ""), flush=True)
        b.screenshot(os.path.join(outdir, "report-screenshot.png"))
    finally:
        b.close()
        srv.shutdown()


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "not-running":
        not_running(sys.argv[2])
    elif len(sys.argv) >= 4 and sys.argv[1] == "live-stop":
        live_stop(sys.argv[2], sys.argv[3], int(sys.argv[4]) if len(sys.argv) >= 5 else None)
    elif len(sys.argv) >= 4 and sys.argv[1] == "start-ride":
        start_ride(sys.argv[2], sys.argv[3])
    elif len(sys.argv) >= 3 and sys.argv[1] == "report":
        report(sys.argv[2])
    else:
        fail(__doc__)
    print("CONSOLE-BROWSER: PASS", flush=True)
