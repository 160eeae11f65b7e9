#!/usr/bin/python3
"""The monitor page in a real browser (issues 39 and 54 part 6).

Debian's chromium, headless, opens the page that web_test_server serves (its status is previsd's
own statusJson), driven over the DevTools protocol (python3-websocket), on an emulated phone held
upright (390×844) and on its side (844×390). It checks what a crew meets:

- while the box starts, the page says so in words and the controls wait;
- the picture changes and the status updates;
- the state reads in plain words (mode, tracking, lighting, REC with the take's name and
  duration, timecode; noise and time left while refining), and the state and the controls are
  on screen without scrolling, upright and on its side;
- the controls are disabled and say why until one signs in; a wrong token is told plainly, the
  right one enables them and is kept across a reload (sessionStorage);
- a reply is a short sentence, never the raw JSON nor the box's paths; a double tap on Record
  sends one request; requests without the token change nothing;
- on a box with control off, the controls are disabled and say so.

    browser_test.py [--all] WEB_TEST_SERVER

--all goes on after a failed check (with short waits) and lists every failure: run against an
earlier page, it shows which checks that page fails. Exit 0 on success, 1 on failure, 77
(skipped) when chromium or python3-websocket is missing. Every wait polls a condition with a
generous limit: a loaded 2-core machine is slow, not wrong.
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
TAKE = "2026-12-06_101200"  # web_test_server's take, in the folder /var/lib/previs/takes
PORTRAIT = (390, 844)
LANDSCAPE = (844, 390)


def skip(reason):
    print(f"SKIP: {reason}")
    sys.exit(77)


class Checks:
    """Stops at the first failure, or with --all records it and goes on (waits cut short)."""

    def __init__(self, keep_going):
        self.keep_going = keep_going
        self.failures = []
        self.count = 0
        self.started = time.monotonic()

    def fail(self, what):
        self.count += 1
        print(f"FAIL: {what}", flush=True)
        if not self.keep_going:
            raise SystemExit(1)
        self.failures.append(what)

    def succeed(self, what):
        self.count += 1
        if self.keep_going:
            print(f"pass: {what}", flush=True)

    def expect(self, what, ok, detail=""):
        if not ok:
            self.fail(f"{what}{': ' + str(detail) if detail else ''}")
        else:
            self.succeed(what)
        return ok

    def wait_for(self, what, condition, timeout=20.0, interval=0.1):
        if self.keep_going:
            timeout = min(timeout, 4.0)
        end = time.monotonic() + timeout
        last = None
        while time.monotonic() < end:
            last = condition()
            if last:
                self.succeed(what)
                return last
            time.sleep(interval)
        self.fail(f"{what} (after {timeout:.0f} s; last value {last!r})")
        return None

    def passed(self, what):
        print(f"ok: {what} ({time.monotonic() - self.started:.1f} s)", flush=True)


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
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
        raise RuntimeError(f"{method}: no answer in {timeout} s")

    def close(self):
        self.ws.close()


class Page:
    """One tab, on an emulated phone screen from its first paint."""

    def __init__(self, devtools, url, size):
        self.devtools = devtools
        target = devtools.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = devtools.call("Target.attachToTarget",
                                     {"targetId": target, "flatten": True})["sessionId"]
        self.screen(size)
        devtools.call("Page.navigate", {"url": url}, self.session)

    def screen(self, size):
        width, height = size
        self.devtools.call("Emulation.setDeviceMetricsOverride",
                           {"width": width, "height": height, "deviceScaleFactor": 2,
                            "mobile": True}, self.session)

    def reload(self):
        self.devtools.call("Page.reload", {"ignoreCache": True}, self.session)

    def eval(self, expression):
        result = self.devtools.call("Runtime.evaluate",
                                    {"expression": expression, "returnByValue": True,
                                     "awaitPromise": True}, self.session)
        if "exceptionDetails" in result:
            return None
        return result["result"].get("value")

    def text(self, element_id):
        return self.eval(f"document.getElementById('{element_id}')?.textContent.trim() ?? null")

    def disabled(self, element_id):
        return self.eval(f"document.getElementById('{element_id}')?.disabled ?? null")

    def shown(self, element_id):
        """Whether the element is rendered (not hidden, not display: none)."""
        return self.eval(f"""(() => {{
            const e = document.getElementById('{element_id}');
            return !!e && e.getClientRects().length > 0;
        }})()""")

    def click(self, element_id, taps=1):
        """A real click (taps=2: a double tap) at the element's centre; False when it is not
        on the page."""
        box = self.eval(f"""(() => {{
            const e = document.getElementById('{element_id}');
            if (!e || e.getClientRects().length === 0) return null;
            e.scrollIntoView({{block: 'center'}});
            const r = e.getBoundingClientRect();
            return {{x: r.left + r.width / 2, y: r.top + r.height / 2}};
        }})()""")
        if not box:
            return False
        for tap in range(1, taps + 1):
            for kind in ("mousePressed", "mouseReleased"):
                self.devtools.call("Input.dispatchMouseEvent",
                                   {"type": kind, "x": box["x"], "y": box["y"], "button": "left",
                                    "clickCount": tap}, self.session)
        return True

    def type_into(self, element_id, text):
        self.eval(f"document.getElementById('{element_id}')?.focus()")
        self.devtools.call("Input.insertText", {"text": text}, self.session)

    def off_screen(self, element_ids):
        """Of `element_ids`, those missing, hidden, with words cut off, or not wholly inside the
        viewport with the page scrolled to its top (what one sees without scrolling)."""
        return self.eval(f"""(() => {{
            window.scrollTo(0, 0);
            const w = window.innerWidth, h = window.innerHeight;
            return {json.dumps(element_ids)}.filter((id) => {{
                const e = document.getElementById(id);
                if (!e || e.getClientRects().length === 0) return true;
                const r = e.getBoundingClientRect();
                const clipped = e.scrollWidth > e.clientWidth + 1;  // words cut off
                return r.width < 1 || r.height < 1 || r.top < 0 || r.left < 0 ||
                       r.bottom > h + 0.5 || r.right > w + 0.5 || clipped;
            }});
        }})()""")

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


STATE = ["mode", "tracking", "lighting", "rec", "timecode"]
CONTROLS = ["preview", "refineButton", "recStart", "recStop", "why"]
# Words a crew should never meet on the page.
DEVELOPER_WORDS = re.compile(r"Bearer|Authorization|\{|\"ok\"|/var/lib|\b40[13]\b|\b200\b")


def developer_words(page):
    return DEVELOPER_WORDS.findall(page.eval("document.body.innerText") or "")


def check_starting(checks, page, server):
    """While the box starts: the page says what it is doing, and the controls wait."""
    checks.wait_for("the page says the box is starting, in words",
                    lambda: page.text("banner") == "Starting: compiling pipelines 3/7")
    checks.expect("while starting, no tracking is not a warning",
                  page.text("tracking") == "No tracking yet", page.text("tracking"))
    checks.expect("the controls are disabled while the box starts", page.disabled("preview"))
    checks.expect("the page says why the controls wait",
                  page.text("why") == "Wait: the box is starting", page.text("why"))
    server.stdin.write(b"ready\n")
    server.stdin.flush()
    checks.wait_for("the starting banner goes once the box runs",
                    lambda: page.eval("document.getElementById('banner')?.hidden") is True)
    checks.passed("starting shown in words")


def check_picture_and_status(checks, page):
    first = checks.wait_for("a stream frame shows in the <img>", page.picture_sample, 30)
    checks.wait_for("the picture changes",
                    lambda: (s := page.picture_sample()) is not None and s != first)
    checks.wait_for("nothing covers the picture once it shows", lambda: page.shown("offline") is
                    False)
    updates = checks.wait_for("the page counts status updates",
                              lambda: page.eval("document.getElementById('state')"
                                                "?.dataset.updates"))
    checks.wait_for("the status updates", lambda: page.eval(
        "document.getElementById('state')?.dataset.updates") != updates)
    checks.passed("picture and status update")


def check_words(checks, page, expected):
    for element_id, words in expected.items():
        checks.wait_for(f"#{element_id} says {words!r}",
                        lambda: (t := page.text(element_id)) is not None and
                        re.fullmatch(words, t))


def check_on_screen(checks, page, size, ids, what):
    page.screen(size)
    fits = checks.wait_for(f"{what} at {size[0]}×{size[1]}: no sideways scrolling",
                           lambda: page.eval(f"document.documentElement.scrollWidth <= {size[0]}"))
    off = page.off_screen(ids)
    checks.expect(f"{what} at {size[0]}×{size[1]}: on screen without scrolling",
                  fits and off == [], f"off screen or missing: {off}")


def check_sign_in(checks, page, port):
    """Controls wait for a sign-in; a wrong token is told plainly; the right one enables them
    and is kept for the browser session (a reload keeps it)."""
    checks.wait_for("the controls say to sign in", lambda: page.text("why") == "Sign in to control")
    checks.expect("the controls are disabled before signing in",
                  all(page.disabled(b) for b in ("preview", "refineButton", "recStart")))
    page.click("preview")
    time.sleep(0.3)  # a request, had the press sent one, has reached the server by now
    web = server_status(port)["web"]
    checks.expect("a press before signing in sends nothing",
                  (web["commands"], web["rejected"]["unauthorized"]) == (0, 0), web["rejected"])

    page.type_into("token", "not-the-token")
    checks.expect("the page has a sign-in button", page.click("signinButton"))
    checks.wait_for("a wrong token is told in plain words", lambda: page.text("result") ==
                    "That token is not right: check it and try again")
    checks.expect("a wrong token leaves the controls disabled", page.disabled("preview"))
    checks.expect("the page shows no developer wording", not developer_words(page),
                  developer_words(page))

    page.type_into("token", TOKEN)
    page.click("signinButton")
    checks.wait_for("the right token signs in", lambda: page.text("result") == "Signed in")
    checks.wait_for("signed in, the controls are enabled",
                    lambda: page.disabled("refineButton") is False and page.text("why") == "")
    checks.expect("the token is kept for the browser session",
                  page.eval("sessionStorage.getItem('previs.token')") == TOKEN)
    checks.expect("the token is not kept on the device for good",
                  page.eval("localStorage.getItem('previs.token')") is None)
    page.reload()
    checks.wait_for("after a reload the page is still signed in",
                    lambda: page.shown("signedIn") and page.disabled("refineButton") is False)
    checks.expect("after a reload the page asks for no token",
                  page.shown("signin") is False and page.shown("signedIn"))
    checks.passed("sign-in")


def check_commands(checks, page, port):
    """Replies in words; refining shows noise and time left; a double tap on Record sends one
    request and REC shows the take's name and duration."""
    page.click("refineButton")
    checks.wait_for("the reply to Refine is a short sentence",
                    lambda: page.text("result") == "Refining")
    check_words(checks, page, {"mode": "Refining",
                               "refine": r"\d+ samples · noise 1\.8% · 12 s left"})
    checks.expect("the server refines", server_status(port)["mode"] == "refine")

    commands = server_status(port)["web"]["commands"]
    page.click("recStart", taps=2)
    checks.expect("the buttons are disabled while a request is in flight",
                  page.disabled("recStop") and page.text("why") == "Sending…", page.text("why"))
    checks.wait_for("the reply to Record names the take",
                    lambda: page.text("result") == f"Recording take {TAKE}")
    check_words(checks, page, {"rec": rf"REC {TAKE} · 0:0\d"})
    checks.wait_for("the buttons come back", lambda: page.disabled("recStop") is False)
    time.sleep(1.5)  # a second request, had one been sent, has reached the server by now
    status = server_status(port)
    checks.expect("a double tap sends one request", status["web"]["commands"] == commands + 1,
                  status["web"]["commands"] - commands)
    checks.expect("the record start reached the server", status["recording"])
    checks.expect("the page shows no developer wording or path", not developer_words(page),
                  developer_words(page))
    checks.passed("commands answered in words")


def check_outside_requests(checks, port):
    before = server_status(port)
    checks.expect("POST /mode without the token is refused",
                  post_without_token(port, "/mode", "toggle") == 401)
    checks.expect("POST /record without the token is refused",
                  post_without_token(port, "/record", "stop") == 401)
    after = server_status(port)
    checks.expect("requests without the token change nothing",
                  (after["mode"], after["recording"]) == (before["mode"], before["recording"]))


def check_layouts(checks, page):
    """Upright and on its side: state and controls on screen; tablet: no sideways scrolling and
    thumb-sized buttons."""
    for size in (PORTRAIT, LANDSCAPE):
        check_on_screen(checks, page, size, STATE + ["refine"] + CONTROLS + ["signout"],
                        "state and controls, signed in, refining and recording")
    page.screen((820, 1180))
    height = checks.wait_for("the tablet layout settles", lambda: page.eval("""(() => {
        const fits = document.documentElement.scrollWidth <= 820;
        return fits ? document.getElementById('preview').getBoundingClientRect().height : null;
    })()"""))
    checks.expect("buttons are thumb-sized (at least 44 px high)", (height or 0) >= 44, height)
    page.screen(PORTRAIT)
    checks.passed("layouts")


def check_control_off(checks, devtools, server_binary, children):
    """A box with control off: the controls are disabled and say so; no sign-in offered."""
    server = start_server(server_binary, ["--token", ""], children)
    if not server:
        return checks.fail("web_test_server (control off) did not start")
    port, _ = server
    page = Page(devtools, f"http://127.0.0.1:{port}/", LANDSCAPE)
    checks.wait_for("with control off the page says so",
                    lambda: page.text("why") == "Control is off on this box")
    checks.expect("with control off the buttons are disabled",
                  all(page.disabled(b) for b in ("preview", "refineButton", "recStart")))
    checks.expect("with control off no sign-in is offered", page.shown("token") is False)
    off = page.off_screen(STATE + CONTROLS)
    checks.expect("control off, on its side: state and reason on screen", off == [], off)
    checks.passed("control off")


def start_child(command, children, stream_name, pattern, timeout, **popen_arguments):
    """Starts `command` (kept in `children`) and waits for `pattern` on its pipe `stream_name`,
    which is then drained: (process, match), or (None, None) when the line does not come."""
    child = subprocess.Popen(command, **popen_arguments)
    children.append(child)
    stream = getattr(child, stream_name)
    match = read_line_matching(stream, pattern, timeout)
    if not match:
        return None, None
    drain(stream)
    return child, match


def start_server(server_binary, arguments, children):
    server, listening = start_child([server_binary, "--fps", "10"] + arguments, children,
                                    "stdout", r"LISTENING (\d+)", 30,
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    return (int(listening.group(1)), server) if server else None


def start_chromium(profile, children):
    chromium, devtools_url = start_child(
        [CHROMIUM, "--headless=new", "--no-sandbox", "--remote-debugging-port=0",
         "--remote-allow-origins=*", f"--user-data-dir={profile}", "--disable-gpu",
         "--no-first-run", "--no-default-browser-check", "--disable-extensions",
         "--disable-background-networking", "--disable-dev-shm-usage", "--mute-audio",
         "--window-size=800,1000", "about:blank"],
        children, "stderr", r"DevTools listening on (ws://\S+)", 60,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    return DevTools(devtools_url.group(1)) if chromium else None


def run(server_binary, checks):
    children = []
    profile = tempfile.mkdtemp(prefix="previs-web-chromium-")
    devtools = None
    try:
        # Each control command takes 1 s, as a record start opening a take may: a second
        # tap arrives while the first request is in flight.
        server = start_server(server_binary,
                              ["--token", TOKEN, "--command-delay-ms", "1000",
                               "--starting", "compiling pipelines 3/7"], children)
        if not server:
            return checks.fail("web_test_server did not start")
        port, process = server
        devtools = start_chromium(profile, children)
        if not devtools:
            return checks.fail("chromium printed no DevTools URL")
        page = Page(devtools, f"http://127.0.0.1:{port}/", PORTRAIT)
        checks.passed("chromium up")

        check_starting(checks, page, process)
        check_picture_and_status(checks, page)
        check_words(checks, page, {"mode": "Preview", "tracking": "Tracking OK · 4 tags",
                                   "lighting": "Lighting OK", "rec": "Not recording",
                                   "timecode": "TC 01:00:00:00"})
        for size in (PORTRAIT, LANDSCAPE):
            check_on_screen(checks, page, size, STATE + CONTROLS + ["token", "signinButton"],
                            "state and controls, signed out")
        page.screen(PORTRAIT)
        checks.passed("state in words, on screen")

        check_sign_in(checks, page, port)
        check_commands(checks, page, port)
        process.stdin.write(b"lost\nlighting off\n")
        process.stdin.flush()
        check_words(checks, page, {"tracking": "Tracking lost",
                                   "lighting": r"Lighting off: CG too dark ×0\.42"})
        check_layouts(checks, page)
        check_outside_requests(checks, port)
        viewers = server_status(port)["web"]["viewers"]
        checks.expect("the page's stream is counted as a viewer", viewers >= 1, viewers)
        check_control_off(checks, devtools, server_binary, children)
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
    arguments = [a for a in sys.argv[1:] if a != "--all"]
    if len(arguments) != 1:
        print("usage: browser_test.py [--all] WEB_TEST_SERVER", file=sys.stderr)
        return 2
    if not os.access(CHROMIUM, os.X_OK):
        skip(f"{CHROMIUM} is not installed (Debian package chromium)")
    try:
        import websocket  # noqa: F401
    except ImportError:
        skip("python3-websocket is not installed")
    checks = Checks(keep_going="--all" in sys.argv[1:])
    run(arguments[0], checks)
    if checks.failures:
        print(f"{len(checks.failures)} of {checks.count} checks failed:\n  " +
              "\n  ".join(checks.failures))
        return 1
    print(f"PASS: {checks.count} checks in {time.monotonic() - checks.started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
