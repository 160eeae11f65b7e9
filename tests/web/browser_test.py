#!/usr/bin/python3
"""The monitor page in a real browser (issue 39).

Debian's chromium, headless, opens the page that web_test_server serves, driven over the DevTools
protocol (python3-websocket). It must see the picture change (two canvas samples of the MJPEG
<img> differ), see the status update (the frame counter moves), and, with the token typed into
the page's field, press the toggle button and see the mode change on the page and on the server;
requests without the token (from the page and from outside) change nothing. Emulated phone and
tablet screens lay the page out without sideways scrolling and with thumb-sized buttons.

    browser_test.py WEB_TEST_SERVER

Exit 0 on success, 1 on failure, 77 (skipped) when chromium or python3-websocket is missing.
Every wait polls a condition with a generous limit: a loaded 2-core machine is slow, not wrong.
"""

import json
import os
import re
import select
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request

TOKEN = "browser-test-token"
CHROMIUM = "/usr/bin/chromium"


def skip(reason):
    print(f"SKIP: {reason}")
    sys.exit(77)


def fail(reason):
    print(f"FAIL: {reason}")
    raise SystemExit(1)


def read_line_matching(stream, pattern, timeout):
    """The first match of `pattern` in the lines of `stream` within `timeout` seconds."""
    end = time.monotonic() + timeout
    buffered = b""
    while time.monotonic() < end:
        ready, _, _ = select.select([stream], [], [], max(0.0, end - time.monotonic()))
        if not ready:
            break
        chunk = os.read(stream.fileno(), 4096)
        if not chunk:
            break
        buffered += chunk
        while b"\n" in buffered:
            line, buffered = buffered.split(b"\n", 1)
            found = re.search(pattern, line.decode(errors="replace"))
            if found:
                return found
    return None


def drain(stream):
    """Keeps reading a child's pipe so that it never blocks on a full one."""
    threading.Thread(target=lambda: [None for _ in iter(lambda: stream.read(4096), b"")],
                     daemon=True).start()


def wait_for(what, condition, timeout=20.0, interval=0.1):
    end = time.monotonic() + timeout
    last = None
    while time.monotonic() < end:
        last = condition()
        if last:
            return last
        time.sleep(interval)
    fail(f"{what} (after {timeout:.0f} s; last value {last!r})")


class DevTools:
    """Just enough of the DevTools protocol: commands on the browser or on one page session."""

    def __init__(self, url):
        import websocket  # python3-websocket
        self.ws = websocket.create_connection(url, timeout=30, suppress_origin=True)
        self.next_id = 0

    def call(self, method, params=None, session=None, timeout=30.0):
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        self.ws.send(json.dumps(message))
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    fail(f"{method}: {reply['error']}")
                return reply.get("result", {})
        fail(f"{method}: no answer in {timeout} s")

    def close(self):
        self.ws.close()


class Page:
    def __init__(self, devtools, url):
        self.devtools = devtools
        target = devtools.call("Target.createTarget", {"url": url})["targetId"]
        self.session = devtools.call("Target.attachToTarget",
                                     {"targetId": target, "flatten": True})["sessionId"]

    def eval(self, expression):
        result = self.devtools.call("Runtime.evaluate",
                                    {"expression": expression, "returnByValue": True,
                                     "awaitPromise": True}, self.session)
        if "exceptionDetails" in result:
            return None
        return result["result"].get("value")

    def text(self, element_id):
        return self.eval(f"document.getElementById('{element_id}')?.textContent ?? null")

    def click(self, element_id, taps=1):
        """A real click (taps=2: a double tap): mouse pressed and released at the button's
        centre, each tap sent as soon as the browser took the one before."""
        box = self.eval(f"""(() => {{
            const e = document.getElementById('{element_id}');
            e.scrollIntoView({{block: 'center'}});
            const r = e.getBoundingClientRect();
            return {{x: r.left + r.width / 2, y: r.top + r.height / 2}};
        }})()""")
        for tap in range(1, taps + 1):
            for kind in ("mousePressed", "mouseReleased"):
                self.devtools.call("Input.dispatchMouseEvent",
                                   {"type": kind, "x": box["x"], "y": box["y"], "button": "left",
                                    "clickCount": tap}, self.session)

    def type_into(self, element_id, text):
        self.eval(f"document.getElementById('{element_id}').focus()")
        self.devtools.call("Input.insertText", {"text": text}, self.session)

    def picture_sample(self):
        """A hash of the <img>'s current frame drawn to a small canvas (null before one shows)."""
        return self.eval("""(() => {
            const img = document.getElementById('stream');
            if (!img || !img.complete || img.naturalWidth === 0) return null;
            const c = document.createElement('canvas');
            c.width = 64; c.height = 36;
            const g = c.getContext('2d');
            g.drawImage(img, 0, 0, 64, 36);
            const d = g.getImageData(0, 0, 64, 36).data;
            let h = 7;
            for (let i = 0; i < d.length; i++) h = (h * 31 + d[i]) >>> 0;
            return h;
        })()""")


def server_status(port):
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/status.json", timeout=10) as r:
        return json.load(r)


def post_without_token(port, path, body):
    request = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=body.encode(),
                                     method="POST")
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def run(server_binary):
    started = time.monotonic()
    children = []
    profile = tempfile.mkdtemp(prefix="previs-web-chromium-")
    devtools = None
    try:
        # Each control command takes 1 s, as a record start opening a take may: a second
        # tap arrives while the first request is in flight.
        server = subprocess.Popen([server_binary, "--token", TOKEN, "--fps", "10",
                                   "--command-delay-ms", "1000"],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        children.append(server)
        listening = read_line_matching(server.stdout, r"LISTENING (\d+)", 30)
        if not listening:
            fail("web_test_server did not start")
        port = int(listening.group(1))
        drain(server.stdout)

        chromium = subprocess.Popen(
            [CHROMIUM, "--headless=new", "--no-sandbox", "--remote-debugging-port=0",
             "--remote-allow-origins=*", f"--user-data-dir={profile}", "--disable-gpu",
             "--no-first-run", "--no-default-browser-check", "--disable-extensions",
             "--disable-background-networking", "--disable-dev-shm-usage", "--mute-audio",
             "--window-size=800,1000", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        children.append(chromium)
        devtools_url = read_line_matching(chromium.stderr, r"DevTools listening on (ws://\S+)", 60)
        if not devtools_url:
            fail("chromium printed no DevTools URL")
        drain(chromium.stderr)
        devtools = DevTools(devtools_url.group(1))
        page = Page(devtools, f"http://127.0.0.1:{port}/")
        print(f"chromium up after {time.monotonic() - started:.1f} s")

        # The picture: a frame shows, then a different one.
        first = wait_for("a stream frame shows in the <img>", page.picture_sample, 30)
        wait_for("the picture changes",
                 lambda: (s := page.picture_sample()) is not None and s != first)
        print(f"picture changes ({time.monotonic() - started:.1f} s)")

        # The status: the fields show and the frame counter moves.
        wait_for("the page shows mode preview", lambda: page.text("mode") == "preview")
        frames = wait_for("the page shows a frame count",
                          lambda: (t := page.text("frames")) and t.isdigit() and t)
        wait_for("the status updates", lambda: (t := page.text("frames")) and t != frames)
        if page.text("timecode") != "01:00:00:00":
            fail(f"timecode shown as {page.text('timecode')!r}")
        if page.text("tracking") != "4 tags":
            fail(f"tracking shown as {page.text('tracking')!r}")
        print(f"status updates ({time.monotonic() - started:.1f} s)")

        # Without the token: the page's press and an outside request change nothing.
        page.click("toggle")
        wait_for("the page reports 401 without the token",
                 lambda: (page.text("result") or "").startswith("401"))
        if post_without_token(port, "/mode", "toggle") != 401:
            fail("POST /mode without the token was not answered 401")
        if post_without_token(port, "/record", "start") != 401:
            fail("POST /record without the token was not answered 401")
        status = server_status(port)
        if status["mode"] != "preview" or status["recording"]:
            fail(f"a request without the token changed the state: {status}")
        if status["web"]["rejected"]["unauthorized"] < 3:
            fail(f"unauthorized requests not counted: {status['web']}")

        # With the token typed into the field: the toggle changes the mode, on the page and on
        # the server, and the token is kept for the next visit.
        page.type_into("token", TOKEN)
        page.click("toggle")
        wait_for("the page reports the toggle accepted",
                 lambda: (page.text("result") or "").startswith("200"))
        wait_for("the page shows mode refine", lambda: page.text("mode") == "refine")
        if server_status(port)["mode"] != "refine":
            fail("the server's mode did not change")
        if page.eval("localStorage.getItem('previs.token')") != TOKEN:
            fail("the token was not kept in localStorage")
        print(f"toggle with the token changes the mode ({time.monotonic() - started:.1f} s)")

        if post_without_token(port, "/mode", "toggle") != 401 or \
                server_status(port)["mode"] != "refine":
            fail("a request without the token changed the mode back")

        # A double tap on Record start sends one request: the buttons are disabled while it is
        # in flight (issue 52: two concurrent starts ended previsd), and come back after it.
        commands = server_status(port)["web"]["commands"]
        page.click("recStart", taps=2)
        if not page.eval("document.getElementById('recStop').disabled"):
            fail("the buttons are not disabled while a request is in flight")
        wait_for("the page reports the record start accepted",
                 lambda: (page.text("result") or "").startswith("200"))
        wait_for("the buttons come back", lambda: not page.eval(
            "document.getElementById('recStart').disabled"))
        time.sleep(1.5)  # a second request, had one been sent, has reached the server by now
        status = server_status(port)
        if status["web"]["commands"] != commands + 1:
            fail(f"a double tap sent {status['web']['commands'] - commands} requests, not 1")
        if not status["recording"]:
            fail("the record start did not reach the server")
        print(f"a double tap sends one request ({time.monotonic() - started:.1f} s)")
        # Phone and tablet: no sideways scrolling, the picture fills the width, buttons a thumb
        # can hit (at least 44 CSS px high, Apple's and Google's guidance).
        for name, width, height in (("phone", 390, 844), ("tablet", 820, 1180)):
            page.devtools.call("Emulation.setDeviceMetricsOverride",
                               {"width": width, "height": height, "deviceScaleFactor": 2,
                                "mobile": True}, page.session)
            layout = wait_for(f"the {name} layout settles", lambda: page.eval(f"""(() => {{
                const img = document.getElementById('stream').getBoundingClientRect();
                const button = document.getElementById('toggle').getBoundingClientRect();
                const fits = document.documentElement.scrollWidth <= {width};
                return fits && img.width > {width} * 0.8 ? {{img: img.width,
                    button: button.height}} : null;
            }})()"""))
            if layout["button"] < 44:
                fail(f"{name}: the toggle button is {layout['button']} px high")
        print(f"phone and tablet layouts fit ({time.monotonic() - started:.1f} s)")

        viewers = server_status(port)["web"]["viewers"]
        if viewers < 1:
            fail(f"the page's stream is not counted as a viewer ({viewers})")
        print(f"PASS in {time.monotonic() - started:.1f} s")
    finally:
        if devtools:
            devtools.close()
        for child in reversed(children):
            if child.stdin:
                child.stdin.close()
            child.terminate()
            try:
                child.wait(timeout=10)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        shutil.rmtree(profile, ignore_errors=True)


def main():
    if len(sys.argv) != 2:
        print("usage: browser_test.py WEB_TEST_SERVER", file=sys.stderr)
        return 2
    if not os.access(CHROMIUM, os.X_OK):
        skip(f"{CHROMIUM} is not installed (Debian package chromium)")
    try:
        import websocket  # noqa: F401
    except ImportError:
        skip("python3-websocket is not installed")
    run(sys.argv[1])
    return 0


if __name__ == "__main__":
    sys.exit(main())
