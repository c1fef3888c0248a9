#!/usr/bin/env python3
"""Drives headless Chromium through the DevTools protocol against the operator console.

Modes:
  not-running URL             the page must say the stack is not running
  live-stop   URL OUTDIR      50 updates in order and live values, a screenshot, the STOP
                              button (a real mouse click) e-stops the stack: motion-core
                              latches, the drives quick-stop, the trip log names the operator
Prints one line per check; exits 1 on the first failure.
"""
import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
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

    def js(self, expr):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True)
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
    finally:
        b.close()


def live_stop(url, outdir):
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
        # The operator presses STOP (a real mouse click on the button).
        b.click("stop-btn")
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
        b.screenshot(os.path.join(outdir, "screenshot-stopped.png"))
    finally:
        b.close()


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "not-running":
        not_running(sys.argv[2])
    elif len(sys.argv) >= 4 and sys.argv[1] == "live-stop":
        live_stop(sys.argv[2], sys.argv[3])
    else:
        fail(__doc__)
    print("CONSOLE-BROWSER: PASS", flush=True)
