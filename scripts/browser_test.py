"""Drive headless Chromium against `fairgrasp view` over the DevTools protocol.

Checks by pixels: the arm is drawn, Step changes the scene, joint slider 1 moves the arm.
Usage: browser_test.py CHROMIUM FAIRGRASP [SCREENSHOT.png]
"""

import base64
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
import zlib

import websocket  # websocket-client


def decode_png(data):
    """RGB(A) 8-bit non-interlaced PNG -> (width, height, channels, rows of bytes)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat = 8, b""
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and colour in (2, 6) and interlace == 0, "unsupported PNG"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    channels = 3 if colour == 2 else 4
    raw, stride, rows, prev = zlib.decompress(idat), width * channels, [], bytearray(width * channels)
    for y in range(height):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b, c = prev[i], prev[i - channels] if i >= channels else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    return width, height, channels, rows


def pixels(png):
    w, h, ch, rows = decode_png(png)
    return [tuple(row[x * ch : x * ch + 3]) for row in rows for x in range(w)]


class Page:
    def __init__(self, ws_url):
        self.ws = websocket.create_connection(ws_url, timeout=60)
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def eval(self, expression):
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        return r["result"].get("value")

    def wait_for(self, expression, what, timeout=60):
        end = time.time() + timeout
        while time.time() < end:
            if self.eval(expression):
                return
            time.sleep(0.2)
        seen = self.eval("JSON.stringify({state, error: $('error').textContent,"
                         " sliders: state && state.joints.map((_, i) => $('joint-' + i).value)})")
        raise AssertionError(f"timed out waiting for {what}; the page had {seen}")

    def scene_shot(self):
        """The scene image as shown on the page, as a list of RGB pixels (and the PNG)."""
        r = self.eval("JSON.stringify($('frame').getBoundingClientRect())")
        rect = json.loads(r)
        clip = {"x": rect["x"], "y": rect["y"], "width": rect["width"], "height": rect["height"], "scale": 1}
        png = base64.b64decode(self.call("Page.captureScreenshot", format="png", clip=clip)["data"])
        return pixels(png), png

    def click(self, x, y):
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)

    def centre(self, element_id, fraction=0.5):
        r = json.loads(self.eval(f"JSON.stringify($('{element_id}').getBoundingClientRect())"))
        return r["x"] + r["width"] * fraction, r["y"] + r["height"] / 2


def settle(page, frames=3):
    """Waits until a few new frames have arrived, so the image shows the latest state."""
    start = page.eval("frameNo")
    page.wait_for(f"frameNo >= {start} + {frames} && $('frame').complete", "new frames")


def arm_pixels(px):
    # The FR5's links are neutral light grey/white; the table is brown, the background blue-grey
    # (205, 214, 224), which the neutrality test leaves out.
    return sum(1 for r, g, b in px if min(r, g, b) > 120 and max(r, g, b) - min(r, g, b) < 8)


def changed(a, b):
    return sum(1 for p, q in zip(a, b) if sum(abs(x - y) for x, y in zip(p, q)) > 30)


def main():
    chrome, fairgrasp = sys.argv[1], sys.argv[2]
    screenshot = sys.argv[3] if len(sys.argv) > 3 else ""
    server = subprocess.Popen([fairgrasp, "view", "--port", "0", "--seed", "0"], stdout=subprocess.PIPE, text=True)
    profile = tempfile.mkdtemp(prefix="fairgrasp-chromium-")
    browser = None
    try:
        line = server.stdout.readline()
        assert "http://" in line, f"fairgrasp view printed {line!r}"
        url = line[line.index("http://") :].strip()
        args = [chrome, "--headless=new", "--disable-gpu", "--remote-debugging-port=0",
                "--remote-allow-origins=*", f"--user-data-dir={profile}", "--window-size=1000,580",
                "--hide-scrollbars", "about:blank"]
        if os.geteuid() == 0:
            args.insert(1, "--no-sandbox")
        browser = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
        for line in browser.stderr:
            if "DevTools listening on" in line:
                port = line.split("ws://")[1].split("/")[0].split(":")[1]
                break
        else:
            raise AssertionError("chromium did not start its DevTools endpoint")
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
        page = Page(next(t for t in targets if t["type"] == "page")["webSocketDebuggerUrl"])
        page.call("Page.enable")
        # The window size flag leaves room for browser chrome even headless; fix the viewport.
        page.call("Emulation.setDeviceMetricsOverride", width=1000, height=580, deviceScaleFactor=1, mobile=False)
        page.call("Page.navigate", url=url)
        page.wait_for("typeof $ === 'function' && $('frame').naturalWidth > 0 && $('joint-0') !== null", "the page")
        settle(page)

        first, png = page.scene_shot()
        arm = arm_pixels(first)
        print(f"arm-coloured pixels: {arm} of {len(first)}")
        assert arm > 1500, "the arm is not visible"

        page.click(*page.centre("step"))
        page.wait_for("state && state.step >= 1", "a step")
        settle(page)
        stepped, _ = page.scene_shot()
        n = changed(first, stepped)
        print(f"pixels changed by Step: {n}")
        assert n > 0, "Step changed nothing on screen"
        # The page after a step (reward terms filled in) is the README's screenshot.
        page.wait_for("$('info').rows.length > 2", "the reward terms")
        if screenshot:
            shot = page.call("Page.captureScreenshot", format="png")["data"]
            with open(screenshot, "wb") as f:
                f.write(base64.b64decode(shot))

        # A click at 80% along slider 1 sets joint 1 far from its home angle.
        start = page.eval("state.joints[0].degrees")
        page.click(*page.centre("joint-0", 0.8))
        page.wait_for(f"state.mode === 'manual' && Math.abs(state.joints[0].degrees - {start}) > 20"
                      " && Math.abs(state.joints[0].degrees - Number($('joint-0').value)) < 3",
                      "joint 1 to reach the slider")
        settle(page)
        moved, _ = page.scene_shot()
        n = changed(stepped, moved)
        print(f"pixels changed by slider 1: {n}")
        assert n > 3000, "moving slider 1 did not move the arm"
        print("browser_test: OK")
    finally:
        if browser:
            browser.terminate()
        server.terminate()


if __name__ == "__main__":
    main()
