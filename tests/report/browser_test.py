#!/usr/bin/env python3
"""The report page in a real browser: headless Chromium (Debian's `chromium`) driven over the
DevTools protocol on a pipe (--remote-debugging-pipe; Python's standard library only).

  browser_test.py SPECBAKE_EXE REFERENCE_PNG WORK_DIR SKY_HOST_EXE [--update]

Bakes a small output folder (a prism twice, a grating, a small sky), writes `specbake report`'s
page, opens it from disk and
  * fails on any console error, uncaught exception, failed load or error the page's own script
    counted (<body data-js-errors>);
  * compares a screenshot of the top of the page (1280 x 2400 CSS px) loosely with REFERENCE_PNG:
    the mean luminance of 16 x 16 px blocks, correlated (layout present), not pixel-exact;
  * checks that the live prism and BRDF lobes draw (their lit fractions);
  * renders the sky bundle's live view (its own sampling.glsl in WebGL2) at a few views into a
    float framebuffer, reads the pixels back and compares each with SKY_HOST_EXE's double
    evaluation of the same source from the same float32 texels and inputs, within the llvmpipe
    GL test's per-pixel bound (texel-coordinate rounding to 8 fractional bits, float32 geometry
    and arithmetic: tests/atmosphere/gl_pixel_bound.hpp).
--update writes the screenshot as the new reference. Exit 77 (skip) only when Chromium is
missing and cannot be installed, or cannot start; the reason is printed.
"""
import base64
import fcntl
import json
import os
import select
import shutil
import struct
import subprocess
import sys
import time
import zlib

SKIP = 77
WIDTH, HEIGHT, BLOCK = 1280, 2400, 16
# Loose comparison of the block grids (see compare()): measured on this page, the same layout
# with other baked numbers, other warnings and other preview pixels keeps r above 0.97; a
# page without its styles falls to ~0.3, a blank page has no correlation at all.
MIN_CORRELATION = 0.9
MAX_MEAN_ABS = 0.06

CONFIG = """specbake: 1
output: out
jobs:
  - name: grating
    kind: diffraction
    procedural: {type: sine-grating, size: 32, dx_um: 0.125, period_um: 1.0, amplitude_um: 0.2}
    table: {size: 16}
    coherence: {length_um: 3}
    tolerance_advisory: true
  - name: prism
    kind: dispersion
    samples: %d
    material: {glass: N-BK7}
  - name: sky
    kind: atmosphere
    orders: 2
    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}
    scene: {points: 6, relative_se: 0.1}
    previews: {size: 64}
"""


def skip(reason):
    print("SKIPPED: " + reason)
    sys.exit(SKIP)


def find_chromium():
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    if os.geteuid() == 0 and shutil.which("apt-get"):
        print("chromium missing: installing Debian's chromium (root)")
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        subprocess.run(["apt-get", "update", "-qq"], env=env, check=False)
        subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", "chromium", "fonts-dejavu-core"],
                       env=env, check=False)
        path = shutil.which("chromium")
        if path:
            return path
        skip("chromium is not installed and `apt-get install chromium` failed")
    skip("chromium is not installed (Debian package `chromium`; scripts/setup.sh installs it) and this user cannot install it")


# ---- PNG (8-bit RGB/RGBA, as Chromium writes them) ---------------------------------------------

def png_decode(data):
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0, "unsupported PNG"
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b = prev[x]
            c = prev[x - bpp] if x >= bpp else 0
            if f == 1:
                line[x] = (line[x] + a) & 255
            elif f == 2:
                line[x] = (line[x] + b) & 255
            elif f == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, bpp, rows


def block_grid(png_bytes):
    """Mean luminance (0..1) of each BLOCK x BLOCK block of the top WIDTH x HEIGHT pixels."""
    w, h, bpp, rows = png_decode(png_bytes)
    if w < WIDTH or h < HEIGHT:
        raise AssertionError("screenshot %dx%d, expected at least %dx%d" % (w, h, WIDTH, HEIGHT))
    grid = []
    for by in range(HEIGHT // BLOCK):
        out = []
        sums = [0.0] * (WIDTH // BLOCK)
        for y in range(by * BLOCK, (by + 1) * BLOCK):
            line = rows[y]
            for x in range(WIDTH):
                i = x * bpp
                sums[x // BLOCK] += 0.2126 * line[i] + 0.7152 * line[i + 1] + 0.0722 * line[i + 2]
        for s in sums:
            out.append(s / (BLOCK * BLOCK * 255.0))
        grid.append(out)
    return [v for row in grid for v in row]


def compare(shot, reference):
    a, b = block_grid(shot), block_grid(reference)
    n = len(a)
    ma, mb = sum(a) / n, sum(b) / n
    cov = sum((x - ma) * (y - mb) for x, y in zip(a, b))
    va = sum((x - ma) ** 2 for x in a)
    vb = sum((y - mb) ** 2 for y in b)
    r = cov / (va * vb) ** 0.5 if va > 0 and vb > 0 else 0.0
    mad = sum(abs(x - y) for x, y in zip(a, b)) / n
    return r, mad


# ---- DevTools protocol over a pipe ----------------------------------------------------------------

class Browser:
    def __init__(self, exe, log_path):
        to_child_r, self.to_child = os.pipe()
        self.from_child, from_child_w = os.pipe()

        def fds():  # the child's fd 3 reads commands, fd 4 writes answers
            r, w = fcntl.fcntl(to_child_r, fcntl.F_DUPFD, 10), fcntl.fcntl(from_child_w, fcntl.F_DUPFD, 10)
            os.dup2(r, 3)
            os.dup2(w, 4)

        self.log = open(log_path, "wb")
        args = [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", "--hide-scrollbars", "--no-first-run", "--no-default-browser-check",
                "--disable-extensions", "--remote-debugging-pipe", "--user-data-dir=" + os.path.dirname(log_path) +
                "/chromium-profile", "--enable-logging=stderr", "--v=0", "about:blank"]
        self.proc = subprocess.Popen(args, preexec_fn=fds, pass_fds=(3, 4), stdout=self.log,
                                     stderr=subprocess.STDOUT)
        os.close(to_child_r)
        os.close(from_child_w)
        self.buf, self.next_id, self.events, self.session = b"", 0, [], None

    def send(self, method, params=None, timeout=60):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if self.session:
            msg["sessionId"] = self.session
        os.write(self.to_child, json.dumps(msg).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            m = self.read(deadline)
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise RuntimeError("%s: %s" % (method, m["error"]))
                return m.get("result", {})
            self.events.append(m)

    def read(self, deadline):
        while b"\0" not in self.buf:
            if time.time() > deadline:
                raise TimeoutError("no answer from chromium")
            ready, _, _ = select.select([self.from_child], [], [], 1.0)
            if ready:
                chunk = os.read(self.from_child, 1 << 20)
                if not chunk:
                    raise EOFError("chromium closed its pipe (exit %s)" % self.proc.poll())
                self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def evaluate(self, expr):
        r = self.send("Runtime.evaluate", {"expression": expr, "returnByValue": True, "awaitPromise": True})
        if "exceptionDetails" in r:
            raise RuntimeError("evaluating %s: %s" % (expr, r["exceptionDetails"]))
        return r["result"].get("value")

    def close(self):
        try:
            self.session = None
            self.send("Browser.close", timeout=10)
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()


def errors_in(events):
    out = []
    for e in events:
        m, p = e.get("method"), e.get("params", {})
        if m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            out.append("exception: " + (d.get("exception", {}).get("description") or d.get("text", "?")))
        elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            out.append("console.%s: %s" % (p["type"], " ".join(str(a.get("value", a.get("description", "")))
                                                                 for a in p.get("args", []))))
        elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            out.append("log: " + p["entry"].get("text", "?") + " " + p["entry"].get("url", ""))
    return out


# The live sky's views checked: sun high, low and below the horizon, from the ground and above.
SKY_VIEWS = [{"sun_elevation_deg": 20, "sun_azimuth_deg": 0, "altitude_km": 0.001},
             {"sun_elevation_deg": 4, "sun_azimuth_deg": 70, "altitude_km": 2.0},
             {"sun_elevation_deg": -3, "sun_azimuth_deg": -120, "altitude_km": 12.0}]
SKY_N = 40


def check_sky(sky_host, bundle, view, gl):
    r = subprocess.run([sky_host, bundle, str(gl["n"])] + ["%.9g" % v for v in gl["sun"]] + ["%.9g" % gl["altitude_km"]],
                       capture_output=True, text=True)
    if r.returncode != 0:
        print("FAIL: sky_host: " + r.stderr)
        return False
    host = json.loads(r.stdout)
    worst, at, lit, over, rel_bounds = 0.0, None, 0, 0, []
    for i, kind in enumerate(host["kind"]):
        px = gl["rgba"][4 * i:4 * i + 4]
        if kind < 0:
            if any(px):
                over += 1
            continue
        lit += 1
        for c in range(3):
            v, b = host["value"][3 * i + c], host["bound"][3 * i + c]
            d = abs(px[c] - v)
            rel_bounds.append(b / abs(v) if v else float("inf"))
            ratio = d / b if b > 0 else (0.0 if d == 0 else float("inf"))
            if ratio > worst:
                worst, at = ratio, (i % gl["n"], i // gl["n"], "RGB"[c], px[c], v, b)
            over += d > b
    rel_bounds.sort()
    print("live sky %s: %d sky pixels on %s; worst |GL - host| / bound %.3g at %s; median bound / value %.2g"
          % (view, lit, gl.get("renderer", "?"), worst, at, rel_bounds[len(rel_bounds) // 2]))
    if lit < SKY_N * SKY_N // 2 or over:
        print("FAIL: %d channel(s) beyond the bound (or outside the circle not 0)" % over)
        return False
    return True


def main():
    exe, reference, work, sky_host = sys.argv[1:5]
    update = "--update" in sys.argv[5:]
    chromium = find_chromium()
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    # the prism twice (3 samples, then 4): its section shows what changed
    for samples in (3, 4):
        with open(os.path.join(work, "c.yaml"), "w") as f:
            f.write(CONFIG % samples)
        r = subprocess.run([exe, "-q", "run", "c.yaml"], cwd=work, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit("bake failed (%d): %s" % (r.returncode, r.stderr))
    page = os.path.join(work, "page.html")
    r = subprocess.run([exe, "report", "out", "--out", page], cwd=work, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("specbake report failed (%d): %s" % (r.returncode, r.stderr))

    log_path = os.path.join(work, "chromium.log")
    b = Browser(chromium, log_path)
    try:
        try:
            target = b.send("Target.createTarget", {"url": "about:blank"}, timeout=60)["targetId"]
            b.session = b.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        except (EOFError, TimeoutError, OSError) as e:
            with open(log_path, "rb") as f:
                tail = f.read()[-2000:].decode(errors="replace")
            skip("chromium did not start (%s); its log ends:\n%s" % (e, tail))
        for domain in ("Runtime", "Log", "Page"):
            b.send(domain + ".enable")
        b.send("Emulation.setDeviceMetricsOverride",
               {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False})
        b.send("Page.navigate", {"url": "file://" + os.path.abspath(page)})
        deadline = time.time() + 120
        while b.evaluate("document.readyState + '/' + (document.body ? document.body.dataset.ready : '')") != "complete/1":
            if time.time() > deadline:
                sys.exit("the page did not finish loading in 120 s (no <body data-ready=1>)")
            time.sleep(0.2)
        state = b.evaluate("JSON.stringify({errors: document.body.dataset.jsErrors,"
                           " box: document.getElementById('js-errors').textContent,"
                           " jobs: document.querySelectorAll('#jobs tbody tr').length,"
                           " images: Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).length})")
        state = json.loads(state)
        shot = base64.b64decode(b.send("Page.captureScreenshot", {"format": "png"})["data"])
        unavailable = b.evaluate("(document.querySelector('.live-sky') || {getAttribute: () => 'no live view on the page'})"
                                 ".getAttribute('data-unavailable')")
        # the live prism and BRDF lobes: drawn. The prism's beams, one unit wide each, on a strip
        # 16 * (max - min IOR offset) + 1 units wide (about 31 for N-BK7 at 3-4 samples) light 10-13 %
        # of it; the grating's lobes at the default light angle and exposure light ~14 % of the disc's
        # square; 4 % is about one beam, or the specular peak and one order.
        lit = b.evaluate("JSON.stringify(['specbakePrism', 'specbakeLobes'].map(r => { const v = Object.values(window[r])[0];"
                         " if (!v) return -1; const px = v.pixels(); let n = 0;"
                         " for (let i = 0; i < px.length; i += 4) n += px[i] + px[i + 1] + px[i + 2] > 60;"
                         " return n / (px.length / 4); }))")
        lit = json.loads(lit)
        renders = []
        if unavailable is None:
            for view in SKY_VIEWS:
                renders.append(json.loads(b.evaluate("JSON.stringify(specbakeSky.sky.radiance(%s, %d))"
                                                     % (json.dumps(view), SKY_N))))
        time.sleep(0.5)  # late console messages
        b.send("Runtime.evaluate", {"expression": "1"})
        errors = errors_in(b.events)
    finally:
        b.close()

    with open(os.path.join(work, "screenshot.png"), "wb") as f:
        f.write(shot)
    failed = False
    for view, fraction in zip(("prism", "BRDF lobes"), lit):
        if fraction < 0.04:
            print("FAIL: the live %s is missing or dark (lit fraction %s)" % (view, fraction))
            failed = True
    if unavailable is not None:
        print("FAIL: the live sky did not run in this Chromium (SwiftShader WebGL2): %s" % unavailable)
        failed = True
    for view, gl in zip(SKY_VIEWS, renders):
        failed |= not check_sky(sky_host, os.path.join(work, "out", "sky", "latest"), view, gl)
    if errors or state["errors"] != "0":
        print("FAIL: errors in the browser:\n  " + "\n  ".join(errors + [state["box"]]))
        failed = True
    if state["jobs"] != 3 or state["images"] != 0:
        print("FAIL: expected 3 job rows and every image decoded; got %s" % state)
        failed = True
    if update:
        shutil.copyfile(os.path.join(work, "screenshot.png"), reference)
        print("wrote the reference " + reference)
    else:
        with open(reference, "rb") as f:
            r, mad = compare(shot, f.read())
        print("screenshot against %s: block correlation %.3f (>= %.2f), mean |difference| %.3f (<= %.2f); "
              "screenshot at %s" % (reference, r, MIN_CORRELATION, mad, MAX_MEAN_ABS, os.path.join(work, "screenshot.png")))
        if r < MIN_CORRELATION or mad > MAX_MEAN_ABS:
            print("FAIL: the page's layout differs from the reference")
            failed = True
    print("console: %d error(s); page: %s; live prism, lobes lit fractions %s" % (len(errors), state, lit))
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
