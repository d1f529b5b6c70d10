"""Check the built study book in a real browser: ``make book-check [PROFILE=paper]``.

Serves results/<profile>/book/ on a local port and opens it in headless Chromium (Debian's
``chromium`` package, driven by playwright: no browser download). From the rendered DOM it checks

* the landing page: the navigation (a sidebar link to every notebook page), the claims table;
* the claims page: the claims table and an anchor ``claim-<id>`` for each claim id it lists;
* one notebook page (``--notebook``, default 04; ``results/<profile>/executed/<name>.html``, where the
  repository keeps it): navigation, at least one figure, and every image
  on it loaded (``complete`` and ``naturalWidth > 0``);
* the search page: a query (``--query``) returns results;
* no request to the book's own server failed (a missing page, image, script or stylesheet).

A screenshot of each page lands in results/<profile>/book/screenshots/. Exit status 0: all held;
1: a check failed (each is named); 2: the book, playwright or chromium is missing (with how to
get it).

    python tools/check_book.py --profile paper [--notebook 04_ood_noise_evaluation] [--chromium PATH]
"""
from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INSTALL_CHROMIUM = ("chromium is missing: install Debian's package with `sudo apt-get install -y chromium` "
                    "(Ubuntu: `sudo snap install chromium`), or pass --chromium /path/to/chrome")
CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium(explicit: str | None) -> str | None:
    if explicit:
        return explicit if Path(explicit).is_file() else None
    return next((p for p in map(shutil.which, CANDIDATES) if p), None)


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # the browser's requests are checked, not logged
        pass


def serve(folder: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    handler = functools.partial(_Quiet, directory=str(folder))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


IMAGES_JS = """(sel) => Array.from(document.querySelectorAll(sel)).map(i => ({
    src: i.getAttribute('src'), ok: i.complete && i.naturalWidth > 0, width: i.naturalWidth}))"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--book", type=Path, help="default: results/<profile>/book")
    ap.add_argument("--notebook", default="04_ood_noise_evaluation", help="the notebook page to check")
    ap.add_argument("--query", default="Kalman", help="what to search for on the search page")
    ap.add_argument("--chromium", help="the browser binary (default: chromium on PATH)")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds per page")
    args = ap.parse_args(argv)
    book = (args.book or ROOT / "results" / args.profile / "book").resolve()
    if not (book / "index.html").is_file():
        print(f"check_book: {book}/index.html is missing: run `make book PROFILE={args.profile}` first")
        return 2
    chromium = find_chromium(args.chromium)
    if chromium is None:
        print(f"check_book: {INSTALL_CHROMIUM}")
        return 2
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("check_book: playwright is missing: `make book-check` installs requirements-book.txt into .venv "
              "(or: .venv/bin/pip install -r requirements-book.txt -c environment.txt)")
        return 2
    nb_dir = f"results/{args.profile}/executed"
    notebooks = sorted(p.stem for p in (book / nb_dir).glob("*.html"))
    if args.notebook not in notebooks:
        print(f"check_book: no page {nb_dir}/{args.notebook}.html in the book; there are {notebooks}")
        return 2
    shots = book / "screenshots"
    shots.mkdir(exist_ok=True)
    failures: list[str] = []
    passed: list[str] = []

    def check(ok: bool, what: str) -> None:
        (passed if ok else failures).append(what)
        print(f"  {'ok  ' if ok else 'FAIL'} {what}")

    server, base = serve(book)
    bad_requests: list[str] = []
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.set_default_timeout(args.timeout * 1000)
            page.on("response", lambda r: r.url.startswith(base) and r.status >= 400
                    and bad_requests.append(f"{r.status} {r.url[len(base):]}"))
            page.on("requestfailed", lambda r: r.url.startswith(base) and bad_requests.append(f"failed {r.url[len(base):]}"))

            def open_page(path: str, shot: str) -> None:
                print(f"{path}  ({chromium})")
                page.goto(f"{base}/{path}", wait_until="load")
                page.screenshot(path=str(shots / shot), full_page=False)

            def nav_links() -> list[str]:
                return page.eval_on_selector_all("nav.bd-docs-nav a, .bd-sidebar-primary nav a",
                                                 "els => els.map(e => e.getAttribute('href'))")

            # the landing page
            open_page("index.html", "index.png")
            links = nav_links()
            missing = [n for n in notebooks if not any(h and h.split("#")[0].endswith(f"{nb_dir}/{n}.html") for h in links)]
            check(not missing, f"landing page: the navigation links every notebook page ({len(notebooks)})"
                  + (f"; missing {missing}" if missing else ""))
            claim_links = page.eval_on_selector_all("table a[href*='claims.html#claim-']", "els => els.length")
            if args.profile == "paper":
                check(claim_links > 0, f"landing page: the claims table is there ({claim_links} claim ids linked to the claims page)")
            check(page.locator("a[href*='search.html'], form[action*='search'], .search-button").count() > 0,
                  "landing page: a search box or link is there")

            # the claims page
            open_page("claims.html", "claims.png")
            rows = page.evaluate("() => { const t = document.querySelector('main table, article table'); "
                                 "return t ? t.querySelectorAll('tbody tr').length : 0 }")
            ids = page.eval_on_selector_all("table a[href^='#claim-']",
                                            "els => [...new Set(els.map(e => e.getAttribute('href').slice(1)))]")
            dangling = [i for i in ids if page.locator(f"[id='{i}']").count() == 0]
            check(rows > 0 and len(ids) > 0 and not dangling,
                  f"claims page: the claims table ({rows} rows) and an anchor for each of {len(ids)} claim ids"
                  + (f"; no anchor for {dangling}" if dangling else ""))

            # one notebook page
            open_page(f"{nb_dir}/{args.notebook}.html", f"{args.notebook}.png")
            page.wait_for_load_state("networkidle")
            figures = page.evaluate(IMAGES_JS, ".cell_output img")
            images = page.evaluate(IMAGES_JS, "article img, main img")
            broken = [i["src"] for i in images if not i["ok"]]
            check(len(figures) > 0 and all(f["ok"] for f in figures),
                  f"{args.notebook}: {len(figures)} output figure(s), all loaded (natural width > 0)")
            check(not broken, f"{args.notebook}: every image on the page loaded ({len(images)})"
                  + (f"; not loaded: {broken}" if broken else ""))
            check(len(nav_links()) >= len(notebooks) and page.locator("a.right-next, a.left-prev").count() > 0,
                  f"{args.notebook}: the navigation (sidebar and previous/next links) is there")
            page.screenshot(path=str(shots / f"{args.notebook}-full.png"), full_page=True)

            # the search page
            open_page(f"search.html?q={args.query}", "search.png")
            try:
                page.wait_for_selector("#search-results li, ul.search li", timeout=args.timeout * 1000)
                hits = page.locator("#search-results li, ul.search li").count()
            except Exception:  # noqa: BLE001 -- playwright's TimeoutError; reported as a failed check
                hits = 0
            check(hits > 0, f"search page: '{args.query}' finds {hits} page(s)")
            page.screenshot(path=str(shots / "search.png"))
            browser.close()
    finally:
        server.shutdown()
    check(not bad_requests, "no request to the book failed" + (f": {bad_requests[:10]}" if bad_requests else ""))
    print(f"check_book: {len(passed)} checks held, {len(failures)} failed; screenshots in {shots}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
