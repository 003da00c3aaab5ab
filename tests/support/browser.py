"""Look at an HTML report the way a person does: in a headless Chromium at a given window width.

No Python browser package is needed: :func:`check_page` copies the page into
a temporary folder with one script injected (and a ``<base>`` so relative
links resolve as from the original), lets Chromium load it with
``--dump-dom``, and the script writes what it measured after the ``load``
event into the DOM, which is all Chromium prints. It checks what a reader
would see as broken:

- every ``img`` loaded (``complete`` and ``naturalWidth > 0``);
- the page is no wider than the window (``scrollWidth <= innerWidth``: no
  horizontal scroll bar for the whole page);
- no element reaches beyond the window's right edge, or beyond the right edge
  of the page's column (``body``'s content box) - unless it is inside a box
  that scrolls or clips it (a wide table scrolling in its own box is fine);
- no image is drawn wider than the box that holds it (a figure cut off or
  sticking out of its column), nor below half its own width (a plot's
  labels shrunk below half their size are not readable: draw it smaller).

Each finding is one line naming the element: its tag (and id/class), the
section title (the nearest ``section``'s ``h2``) and the figure caption or
table caption when there is one. An empty list means the page passed.

Chromium is Debian's ``chromium`` (``.ci/run`` installs it where it can);
:func:`chromium_executable` returns None when there is none, and tests skip.
One page takes about 1 s on an idle 2-core machine and 2-3 s on a loaded one,
whatever its size (30 kB or 2.4 MB of embedded PNGs): Chromium's start
dominates. A browser confined away from the temporary folder (a snap) cannot
open the copy: that is a ``RuntimeError``, never a pass.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

__all__ = ["chromium_executable", "check_page", "SKIP_REASON"]

_NAMES = ("chromium", "chromium-browser", "google-chrome")
_MARK = "robocal-page-check"

SKIP_REASON = ("no headless browser (chromium, chromium-browser or google-chrome) on PATH: "
               "report pages are not checked in a browser (Debian: apt-get install chromium; .ci/run does)")

# Runs after 'load' (all images loaded or failed). A setTimeout lets the last
# layout settle; with --virtual-time-budget Chromium waits for it without
# wall-clock delay. The findings replace the page so that --dump-dom prints a
# few lines, not the megabytes of embedded PNGs.
_SCRIPT = r"""
<script>
window.addEventListener('load', () => setTimeout(() => {
  const out = [];
  try {
    // the width a reader has: the window less a vertical scroll bar, if any
    const W = document.documentElement.clientWidth;
    const de = document.documentElement;
    const px = v => Math.round(v);
    const describe = el => {
      let s = el.tagName.toLowerCase();
      if (el.id) s += '#' + el.id;
      if (typeof el.className === 'string' && el.className.trim()) s += '.' + el.className.trim().split(/\s+/).join('.');
      const sec = el.closest('section');
      const h = sec && sec.querySelector('h2,h3');
      if (h) s += ' in section "' + h.textContent.trim() + '"';
      const fig = el.closest('figure');
      const fc = fig && fig.querySelector('figcaption');
      if (fc) s += ', figure "' + fc.textContent.trim().slice(0, 80) + '"';
      else if (el.tagName === 'IMG' && el.alt) s += ', image "' + el.alt.slice(0, 80) + '"';
      const tab = el.closest('table');
      const tc = tab && tab.querySelector('caption');
      if (tc) s += ', table "' + tc.textContent.trim().slice(0, 80) + '"';
      else if (tab) s += ', table with columns "' + Array.from(tab.querySelectorAll('th')).slice(0, 4)
          .map(t => t.textContent.trim()).join('", "') + '"';
      if (!sec && !fig && !tab) {
        const t = (el.textContent || '').trim().replace(/\s+/g, ' ').slice(0, 40);
        if (t) s += ' "' + t + '"';
      }
      return s;
    };
    // An element inside a box that scrolls or clips horizontally is seen
    // through that box; the box itself is what is measured.
    const clipped = el => {
      for (let a = el.parentElement; a && a !== document.body && a !== de; a = a.parentElement) {
        if (getComputedStyle(a).overflowX !== 'visible') return true;
      }
      return false;
    };
    const body = document.body;
    const bs = getComputedStyle(body);
    const colRight = body.getBoundingClientRect().right - parseFloat(bs.paddingRight) - parseFloat(bs.borderRightWidth);
    if (de.scrollWidth > W) out.push('page: ' + de.scrollWidth + ' px wide in a ' + W + ' px wide window (horizontal scroll bar)');
    for (const img of document.images) {
      if (!(img.complete && img.naturalWidth > 0)) {
        out.push(describe(img) + ': image did not load (src ' + (img.getAttribute('src') || '').slice(0, 60) + ')');
      }
    }
    const wide = new Set();
    for (const el of body.querySelectorAll('*')) {
      if (el.tagName === 'SCRIPT' || clipped(el)) continue;
      const r = el.getBoundingClientRect();
      if (r.width === 0 && r.height === 0) continue;
      if (r.right > W + 0.5) {
        wide.add(el);
        if (!wide.has(el.parentElement)) out.push(describe(el) + ': right edge at ' + px(r.right) + ' px, beyond the ' + W + ' px window');
      } else if (r.right > colRight + 0.5) {
        wide.add(el);
        if (!wide.has(el.parentElement)) out.push(describe(el) + ': right edge at ' + px(r.right) + ' px, beyond the page column (' + px(colRight) + ' px)');
      }
      if (el.tagName === 'IMG' && el.parentElement) {
        const p = el.parentElement, ps = getComputedStyle(p);
        const inner = p.getBoundingClientRect().width - parseFloat(ps.paddingLeft) - parseFloat(ps.paddingRight)
                      - parseFloat(ps.borderLeftWidth) - parseFloat(ps.borderRightWidth);
        if (r.width > inner + 0.5) out.push(describe(el) + ': drawn ' + px(r.width) + ' px wide in a ' + px(inner) + ' px box');
        // scaled to the column is fine; scaled below half, a plot's labels are too small to read
        if (el.naturalWidth > 0 && r.width < 0.5 * el.naturalWidth) {
          out.push(describe(el) + ': drawn at ' + px(100 * r.width / el.naturalWidth) + ' % of its ' + el.naturalWidth
                   + ' px width: too small to read');
        }
      }
    }
    // Text is not an element: a long word overflows its paragraph's box
    // without moving the box's edge, so text runs are measured themselves.
    const walker = document.createTreeWalker(body, NodeFilter.SHOW_TEXT);
    const range = document.createRange();
    for (let t = walker.nextNode(); t; t = walker.nextNode()) {
      const el = t.parentElement;
      if (!el || !t.textContent.trim() || el.tagName === 'SCRIPT' || el.tagName === 'STYLE' || wide.has(el)) continue;
      if (getComputedStyle(el).overflowX !== 'visible' || clipped(el)) continue;
      range.selectNodeContents(t);
      const r = range.getBoundingClientRect();
      if (r.right > Math.min(W, colRight) + 0.5) {
        wide.add(el);
        out.push(describe(el) + ': text "' + t.textContent.trim().slice(0, 30) + '…" runs to ' + px(r.right)
                 + ' px, beyond the ' + (r.right > W ? W + ' px window' : 'page column (' + px(colRight) + ' px)'));
      }
    }
  } catch (e) {
    out.push('page check failed: ' + e);  // a finding, so that it cannot read as a clean page
  }
  const pre = document.createElement('pre');
  pre.id = 'MARK';
  pre.textContent = JSON.stringify(out);
  document.body.replaceChildren(pre);
  document.head.replaceChildren();
}, 0));
</script>
""".replace("MARK", _MARK)


def chromium_executable() -> str | None:
    """Path of a Chromium-family browser on PATH (chromium, chromium-browser, google-chrome), or None."""
    for name in _NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


def check_page(html_path, *, width: int = 1400, height: int = 900, timeout: float = 60.0) -> list[str]:
    """Problems a reader of ``html_path`` would see in a ``width`` px wide window; [] when none.

    Raises ``RuntimeError`` when no browser is installed (callers skip first,
    see :func:`chromium_executable`) or when the browser did not run the
    check (that must not read as a page without problems).
    """
    exe = chromium_executable()
    if exe is None:
        raise RuntimeError(SKIP_REASON)
    src = Path(html_path).resolve()
    text = src.read_text(encoding="utf-8")
    base = f'<base href="{html.escape(src.parent.as_uri())}/">'
    # <base> right after <head> (or first thing) so that relative src/href keep
    # pointing next to the original; the script goes last in the document.
    m = re.search(r"<head[^>]*>", text, re.IGNORECASE)
    text = text[: m.end()] + base + text[m.end():] if m else base + text
    m = None
    for m in re.finditer(r"</body\s*>", text, re.IGNORECASE):
        pass
    text = text[: m.start()] + _SCRIPT + text[m.start():] if m else text + _SCRIPT
    with tempfile.TemporaryDirectory(prefix="robocal-page-", ignore_cleanup_errors=True) as tmp:
        page = Path(tmp) / "page.html"
        page.write_text(text, encoding="utf-8")
        cmd = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--no-first-run", "--disable-extensions",
               f"--user-data-dir={tmp}/profile", f"--window-size={width},{height}",
               "--virtual-time-budget=10000", "--dump-dom", page.as_uri()]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"{exe} did not finish {src.name} within {timeout:g} s") from None
    found = re.search(rf'<pre id="{_MARK}">(.*?)</pre>', proc.stdout, re.DOTALL)
    if found is None:
        tail = "\n".join([ln for ln in proc.stderr.strip().splitlines() if "dbus" not in ln][-3:])
        raise RuntimeError(f"{exe} did not run the page check on {src.name} (exit {proc.returncode}): {tail}")
    return [str(s) for s in json.loads(html.unescape(found.group(1)))]
