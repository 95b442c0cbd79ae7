#!/usr/bin/env python3
"""Every Kitchen-R page in headless Chromium, as a visitor, a team and the organiser.

Run by the end-to-end test `tests/e2e/browser.rs` against a real server that has run a small
policy evaluation; it can also be run by hand against any server:

    python3 tests/browser/check_pages.py --base http://127.0.0.1:8080 \
        --team-token T --admin-token A --dev-submission 3 --videos 3 --screenshots /tmp/shots

Each page is opened at desktop width (1280 px) and at 375 px (a small phone), and fails the
run on:
- a console error or an uncaught page error (a Content-Security-Policy violation is one);
- a same-origin request answered 4xx/5xx, or a request that failed outright (one Chromium
  cancels itself, `net::ERR_ABORTED`, is not a failure: that is how it switches a video to
  range requests and how it drops a page's pending images when the next page opens);
- a same-origin link, image, video or stylesheet address answering >= 400, or an image that
  does not decode;
- horizontal overflow at 375 px: `document.documentElement.scrollWidth` wider than the window
  (a wide table may scroll inside its own box; the page itself may not);
- on a dev submission page: fewer `<video>` elements than `--videos`, or a video that does not
  reach readyState >= 2 (a decoded frame) with a duration > 0 and a frame size.

One answer is expected and not a failure: `/admin` is the organiser console's login form and
answers 401 to anyone not logged in as the organiser (it is shown, as such, to the visitor and
the team; Chromium logs the 401 of the document itself as a console error, which is dropped).

Pages are found by following the same-origin links of the start pages (the contest home links
the API docs, the leaderboard links each row's summary, ...), at most `--max-pages` per visitor.
A PNG screenshot of every page at both widths goes to `--screenshots` (default: the
`KITCHEN_R_SCREENSHOTS` environment variable, else a new temporary directory); the directory is
printed. Exit status: 0 when every check passed, 1 with every failure listed otherwise, 2 when
the browser could not be started.

`--save-submission-shot FILE` also saves the team's first dev submission page at desktop width,
each video showing its middle frame: that is how `docs/img/submission-page.png` (the README's
and docs/reference/pages.md's picture) is made, from a team's 3-episode dev run of the starter kit's policy.

Chromium is the system's (`--chromium`, default /usr/bin/chromium: Debian's `chromium`
package); Playwright downloads no browser of its own.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from dataclasses import dataclass, field
from urllib.parse import urldefrag, urljoin, urlsplit

DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 375, "height": 812}
# How long one video may take to load and decode its first frame (a debug server, 2 cores).
VIDEO_TIMEOUT_MS = 30_000
# Pages behind a token that answer 401 with their login form to whoever is not logged in.
LOGIN_401 = {"/admin"}

try:
    from playwright.sync_api import Error as PlaywrightError
    from playwright.sync_api import sync_playwright
except ImportError:
    sys.exit(
        "check_pages.py needs Playwright for Python: "
        "python3 -m pip install -r scripts/test-requirements.txt"
    )


@dataclass
class Report:
    failures: list[str] = field(default_factory=list)
    pages: list[str] = field(default_factory=list)
    shots: int = 0
    videos: int = 0

    def fail(self, where: str, what: str) -> None:
        self.failures.append(f"{where}: {what}")


# Media addresses are checked by the page's own <video> (ranges), not fetched whole as links.
LINK_JS = """() => {
  const out = [];
  for (const a of document.querySelectorAll('a[href]')) out.push(a.href);
  for (const i of document.querySelectorAll('img[src]')) out.push(i.src);
  for (const l of document.querySelectorAll('link[href]')) out.push(l.href);
  for (const v of document.querySelectorAll('video[src], video source[src], video[poster]')) {
    if (v.getAttribute('poster')) out.push(new URL(v.getAttribute('poster'), document.baseURI).href);
    if (v.getAttribute('src')) out.push(new URL(v.getAttribute('src'), document.baseURI).href);
  }
  return out;
}"""

# Loads every image (lazy ones too, for the screenshots) and lists those that do not decode.
IMAGES_JS = """async () => {
  const imgs = [...document.images];
  for (const i of imgs) i.loading = 'eager';
  await Promise.all(imgs.map((i) => i.decode().catch(() => null)));
  return imgs.filter((i) => !(i.complete && i.naturalWidth > 0)).map((i) => i.currentSrc || i.src);
}"""

# Loads every <video> and waits for a decoded frame; returns one record per video.
VIDEO_JS = """async (timeoutMs) => {
  const videos = [...document.querySelectorAll('video')];
  const one = (v) => new Promise((resolve) => {
    const done = () => resolve({
      src: v.currentSrc || v.getAttribute('src') || (v.querySelector('source') || {}).src || '',
      readyState: v.readyState, duration: v.duration, width: v.videoWidth, height: v.videoHeight,
      error: v.error ? `MediaError ${v.error.code}: ${v.error.message}` : null,
    });
    if (v.readyState >= 2) return done();
    const timer = setTimeout(done, timeoutMs);
    const finish = () => { clearTimeout(timer); done(); };
    v.addEventListener('loadeddata', finish, { once: true });
    v.addEventListener('error', finish, { once: true });
    // A video with preload=none or metadata loads no frame until asked to.
    v.preload = 'auto';
    v.muted = true;
    v.load();
  });
  return Promise.all(videos.map(one));
}"""

# Shows a frame from the middle of every <video> (for a screenshot): seek, wait until drawn.
SEEK_JS = """async (timeoutMs) => {
  await Promise.all([...document.querySelectorAll('video')].map((v) => new Promise((resolve) => {
    const timer = setTimeout(resolve, timeoutMs);
    v.addEventListener('seeked', () => { clearTimeout(timer); resolve(); }, { once: true });
    v.currentTime = (v.duration || 0) / 2;
  })));
}"""

OVERFLOW_JS = """() => {
  const w = window.innerWidth;
  const wide = [];
  for (const el of document.body.querySelectorAll('*')) {
    const r = el.getBoundingClientRect();
    if (r.right > w + 0.5 && r.width > 0) {
      let p = el.parentElement, clipped = false;
      while (p && p !== document.body) {
        const s = getComputedStyle(p);
        if (['auto', 'scroll', 'hidden'].includes(s.overflowX)) { clipped = true; break; }
        p = p.parentElement;
      }
      const name = el.tagName.toLowerCase() + (el.className ? '.' + el.className : '');
      if (!clipped) wide.push(`${name} (right edge ${r.right.toFixed(1)} px)`);
    }
  }
  // The innermost culprits first: their ancestors only contain them.
  wide.reverse();
  return { scrollWidth: document.documentElement.scrollWidth, width: w, wide: wide.slice(0, 5) };
}"""


class Visitor:
    """One browser context (a visitor, a team, the organiser) and the checks of its pages."""

    def __init__(self, browser, base: str, name: str, shots: str, report: Report, max_pages: int):
        self.base = base.rstrip("/")
        self.origin = urlsplit(self.base).netloc
        self.name = name
        self.shots = shots
        self.report = report
        self.max_pages = max_pages
        self.context = browser.new_context(viewport=DESKTOP)
        # Generous: CI runs this beside the other end-to-end tests on two cores.
        self.context.set_default_timeout(60_000)
        self.page = self.context.new_page()
        self.events: list[str] = []
        self.links: dict[str, int] = {}
        self.seen: set[str] = set()
        self.page.on("console", self._console)
        self.expect_401: str | None = None
        self.page.on("pageerror", lambda e: self.events.append(f"page error: {e}"))
        self.page.on("requestfailed", self._request_failed)
        self.page.on("response", self._response)

    def _console(self, msg) -> None:
        if msg.type != "error":
            return
        if self.expect_401 and msg.location.get("url") == self.expect_401 and "status of 401" in msg.text:
            return
        at = msg.location.get("url") or ""
        self.events.append(f"console error: {msg.text}" + (f" ({at})" if at else ""))

    def _request_failed(self, req) -> None:
        why = req.failure or "failed"
        if "ERR_ABORTED" in why:
            return
        self.events.append(f"request failed: {req.method} {req.url}: {why}")

    def _response(self, resp) -> None:
        if not self.same_origin(resp.url) or resp.status < 400:
            return
        if resp.status == 401 and resp.url == self.expect_401 and resp.request.resource_type == "document":
            return
        self.events.append(f"{resp.request.method} {resp.url} answered {resp.status}")

    def login_401(self, url: str) -> bool:
        """Whether `url` is a login page that answers this visitor 401 by design."""
        return self.name != "admin" and urlsplit(url).path in LOGIN_401

    def same_origin(self, url: str) -> bool:
        return urlsplit(url).netloc == self.origin and urlsplit(url).scheme in ("http", "https")

    def url(self, path: str) -> str:
        return urljoin(self.base + "/", path.lstrip("/"))

    def where(self, url: str) -> str:
        s = urlsplit(url)
        return f"[{self.name}] {s.path}{'?' + s.query if s.query else ''}"

    def flush(self, where: str) -> None:
        for e in self.events:
            self.report.fail(where, e)
        self.events.clear()

    def login(self, form_path: str, token: str, landing: str) -> None:
        """Log in through the page's form (its CSRF field comes with it)."""
        where = f"[{self.name}] login at {form_path}"
        url = self.url(form_path)
        self.expect_401 = url if urlsplit(url).path in LOGIN_401 else None
        self.page.goto(url, wait_until="load")
        self.page.fill("input[name=token]", token)
        with self.page.expect_navigation(wait_until="load"):
            self.page.click("form:has(input[name=token]) button, form:has(input[name=token]) [type=submit]")
        got = urlsplit(self.page.url).path
        if got != landing:
            self.report.fail(where, f"expected to land on {landing}, landed on {self.page.url}")
        self.flush(where)
        self.expect_401 = None

    def crawl(self, starts: list[str], videos: dict[str, int]) -> None:
        """Open `starts`, then every same-origin HTML page they link to, breadth first."""
        queue = [self.url(p) for p in starts]
        while queue and len(self.seen) < self.max_pages:
            url = urldefrag(queue.pop(0))[0]
            if url in self.seen:
                continue
            self.seen.add(url)
            try:
                links = self.visit(url, videos.get(urlsplit(url).path, 0))
            except PlaywrightError as e:
                self.report.fail(self.where(url), f"the browser failed on this page: {e}")
                self.flush(self.where(url))
                continue
            for link in links:
                if link not in self.seen and self._is_page(link):
                    queue.append(link)

    def _is_page(self, url: str) -> bool:
        path = urlsplit(url).path
        if not self.same_origin(url) or path.startswith("/api/v1/"):
            return False
        return not re.search(r"\.(png|svg|mp4|webm|json|jsonl|txt|csv|zip|gz)$", path)

    def visit(self, url: str, want_videos: int) -> list[str]:
        where = self.where(url)
        self.report.pages.append(where)
        self.page.set_viewport_size(DESKTOP)
        self.expect_401 = url if self.login_401(url) else None
        try:
            resp = self.page.goto(url, wait_until="load")
        except PlaywrightError as e:
            self.report.fail(where, f"did not load: {e}")
            return []
        expected = 401 if self.expect_401 else 200
        if resp is None or resp.status != expected:
            self.report.fail(where, f"answered {resp.status if resp else 'nothing'}, expected {expected}")
        if resp is not None and "text/html" not in (resp.headers.get("content-type") or ""):
            self.flush(where)
            return []
        for src in self.page.evaluate(IMAGES_JS):
            self.report.fail(where, f"image {src} does not decode")
        if want_videos:
            self.check_videos(where, want_videos)
        self.shoot(url, "desktop")
        self.page.set_viewport_size(PHONE)
        self.page.reload(wait_until="load")
        self.page.evaluate(IMAGES_JS)
        o = self.page.evaluate(OVERFLOW_JS)
        if o["scrollWidth"] > o["width"]:
            self.report.fail(
                where,
                f"wider than a {o['width']} px screen: scrollWidth {o['scrollWidth']} px; "
                f"too wide: {', '.join(o['wide']) or 'unknown element'}",
            )
        self.shoot(url, "375")
        links = [urldefrag(u)[0] for u in self.page.evaluate(LINK_JS)]
        self.flush(where)
        self.expect_401 = None
        for link in sorted(set(links)):
            if self.same_origin(link):
                self.check_link(where, link)
        return links

    def check_videos(self, where: str, want: int) -> None:
        records = self.page.evaluate(VIDEO_JS, VIDEO_TIMEOUT_MS)
        if len(records) < want:
            self.report.fail(where, f"{len(records)} <video> elements, expected one per dev episode ({want})")
        for r in records:
            ok = (
                r["error"] is None
                and r["readyState"] >= 2
                and isinstance(r["duration"], (int, float))
                and r["duration"] > 0
                and r["width"] > 0
            )
            if ok:
                self.report.videos += 1
            else:
                self.report.fail(
                    where,
                    f"video {r['src']} did not decode a frame: readyState {r['readyState']}, "
                    f"duration {r['duration']}, size {r['width']}x{r['height']}, error {r['error']}",
                )

    def check_link(self, where: str, link: str) -> None:
        if link not in self.links:
            try:
                r = self.context.request.get(link, max_redirects=5, timeout=30_000)
                self.links[link] = r.status
                r.dispose()
            except PlaywrightError as e:
                self.report.fail(where, f"link {link}: {e}")
                self.links[link] = 0
                return
        status = self.links[link]
        if status >= 400 and not (status == 401 and self.login_401(link)):
            self.report.fail(where, f"link {link} answers {status}")

    def shoot(self, url: str, width: str) -> None:
        s = urlsplit(url)
        slug = re.sub(r"[^A-Za-z0-9]+", "-", f"{s.path}{'-' + s.query if s.query else ''}").strip("-")
        path = os.path.join(self.shots, f"{self.name}-{slug or 'index'}-{width}.png")
        self.page.screenshot(path=path, full_page=True)
        self.report.shots += 1

    def logout(self, page: str, landing: str, gated: str) -> None:
        """Log out with the page's form (CSRF field included); `gated` must then send to a login."""
        where = f"[{self.name}] logout from {page}"
        self.page.goto(self.url(page), wait_until="load")
        with self.page.expect_navigation(wait_until="load"):
            self.page.click("form[action$='/logout'] button")
        if urlsplit(self.page.url).path != landing:
            self.report.fail(where, f"expected to land on {landing}, landed on {self.page.url}")
        self.page.goto(self.url(gated), wait_until="load")
        if "/login" not in urlsplit(self.page.url).path:
            self.report.fail(where, f"{gated} still opens after logging out ({self.page.url})")
        self.flush(where)

    def close(self) -> None:
        self.context.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="the server's base URL, e.g. http://127.0.0.1:8080")
    ap.add_argument("--team-token", required=True, help="a team's token (logged in through /team/login)")
    ap.add_argument("--admin-token", required=True, help="the organiser token (logged in through /admin)")
    ap.add_argument(
        "--dev-submission",
        action="append",
        default=[],
        metavar="VISITOR:ID",
        help="a finished dev policy submission to open as `team` or `admin`, e.g. team:2 (repeatable)",
    )
    ap.add_argument("--videos", type=int, default=0, help="<video> elements a dev submission page must have")
    ap.add_argument("--page", action="append", default=[], help="another path to start from (repeatable)")
    ap.add_argument("--chromium", default="/usr/bin/chromium", help="the Chromium binary")
    ap.add_argument("--screenshots", default=os.environ.get("KITCHEN_R_SCREENSHOTS"), help="where PNGs go")
    ap.add_argument("--max-pages", type=int, default=40, help="pages opened per visitor at most")
    ap.add_argument("--save-submission-shot", help="also save the first dev submission page (desktop) here")
    a = ap.parse_args()

    if not os.access(a.chromium, os.X_OK):
        print(f"no Chromium at {a.chromium}: install Debian's `chromium` package", file=sys.stderr)
        return 2
    shots = a.screenshots or tempfile.mkdtemp(prefix="kitchen-r-screenshots-")
    os.makedirs(shots, exist_ok=True)
    print(f"screenshots: {shots}", flush=True)
    subs: dict[str, list[str]] = {"team": [], "admin": []}
    for spec in a.dev_submission:
        who, _, sid = spec.partition(":")
        if who not in subs or not sid.isdigit():
            ap.error(f"--dev-submission takes team:ID or admin:ID, not {spec!r}")
        subs[who].append(f"/submissions/{sid}")

    report = Report()
    with sync_playwright() as p:
        try:
            browser = p.chromium.launch(executable_path=a.chromium, args=["--no-sandbox"])
        except PlaywrightError as e:
            print(f"could not start {a.chromium}: {e}", file=sys.stderr)
            return 2
        public = ["/", "/?split=dev", "/contest", "/team/login", "/admin", *a.page]
        visitors = [
            ("visitor", None, public),
            ("team", ("/team/login", a.team_token, "/team"), ["/team", *subs["team"], *public]),
            ("admin", ("/admin", a.admin_token, "/admin"), ["/admin", *subs["admin"], *public]),
        ]
        for name, login, starts in visitors:
            v = Visitor(browser, a.base, name, shots, report, a.max_pages)
            if login:
                v.login(*login)
            videos = {path: a.videos for path in subs.get(name, [])}
            v.crawl(starts, videos)
            if name == "team" and a.save_submission_shot and subs["team"]:
                v.page.set_viewport_size(DESKTOP)
                v.page.goto(v.url(subs["team"][0]), wait_until="load")
                v.page.evaluate(VIDEO_JS, VIDEO_TIMEOUT_MS)
                v.page.evaluate(SEEK_JS, VIDEO_TIMEOUT_MS)
                v.page.screenshot(path=a.save_submission_shot, full_page=True)
            if name == "team":
                v.logout("/team", "/contest", "/team")
            v.close()
        browser.close()

    print(f"{len(report.pages)} pages, {report.shots} screenshots, {report.videos} videos decoded")
    for where in report.pages:
        print(f"  {where}")
    if report.failures:
        print(f"{len(report.failures)} problems:")
        for f in report.failures:
            print(f"  {f}")
        return 1
    print("all pages passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
