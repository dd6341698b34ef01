"""Page images of a printed report for a layout regression (issue 29: "keep page images of each in
the test data").

The simulated runs' numbers vary a little with the BLAS kernel, and a digit is a few pixels, so
pages are not compared pixel for pixel. Each page is rendered by poppler (``pdftoppm -r 20
-gray``) and reduced to a coarse *ink map*: the fraction of ink in every block of
``BLOCK`` × ``BLOCK`` pixels (a 5 mm square), kept in 16 levels. That is a page image a person can
look at (every block of a run's pages side by side in one PNG) and what is compared:

* a block counts as changed where its ink differs by more than ``INK_STEP`` from every block of
  the other page within one block (so a line that moves by a few points, a wider number or a
  plot's bars at slightly other heights do not count);
* a page fails where more than ``MAX_CHANGED`` of its blocks changed: a table moved to another
  page, a plot resized or dropped, a section added or a page gone changes hundreds of blocks;
  a changed digit changes none.

The structural facts are compared exactly beside it (page count, the headings on each page as
pdftotext reads them), so that an orphaned heading, which moves only a line of blocks, is caught
by name.

``STATION_UPDATE_REPORT_PAGES=1`` rewrites the references from the run being tested
(docs/report.md, "Layout regression").

The page images belong to the renderer that printed them: Chromium's version and the installed
fonts (:func:`renderer`), kept beside them. Another renderer lays text out otherwise (a line
wraps, a table is carried to the next page), so under another one :func:`structure_problems`
compares what does not depend on it: the report's headings in their order, each one found in the
printed text, and the page count within one page. Under the references' own renderer it compares
page by page (the headings on each page, the ink maps). Nothing is left uncompared with a warning.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import matplotlib.image as mimage
import numpy as np

#: the reference ink maps and page facts (one PNG per run, one JSON for all)
DATA = Path(__file__).parent / "data" / "report_pages"
UPDATE_ENV = "STATION_UPDATE_REPORT_PAGES"

DPI = 20  # the rendering: a line of 9 pt text is ~3 px high, a digit ~2 px wide
BLOCK = 4  # px of the rendering per ink-map block: 5.1 mm on paper
LEVELS = 15  # ink kept in 16 levels (0 … 15) in the PNG
INK_STEP = 0.25  # a block differs when its ink differs by more than this from every neighbour's
MAX_CHANGED = 0.02  # the share of a page's blocks that may differ


def ink_maps(pdf: Path) -> list[np.ndarray]:
    """Every page of ``pdf`` as a (rows, cols) ink map: ink fraction 0 … 1 per block, quantised to
    ``LEVELS`` levels."""
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(["pdftoppm", "-r", str(DPI), "-gray", "-png", str(pdf), f"{tmp}/p"], check=True,
                       capture_output=True)
        pages = sorted(Path(tmp).glob("p-*.png"), key=lambda p: int(p.stem.split("-")[1]))
        return [_ink_map(mimage.imread(str(p))) for p in pages]


def _ink_map(image: np.ndarray) -> np.ndarray:
    grey = image[..., 0] if image.ndim == 3 else image  # pdftoppm writes grey as RGB
    ink = 1.0 - grey.astype(float)
    h, w = (ink.shape[0] // BLOCK) * BLOCK, (ink.shape[1] // BLOCK) * BLOCK
    blocks = ink[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK).mean(axis=(1, 3))
    # ink of a text line at 20 dpi covers ~a third of its blocks: stretch so that it reads as ink
    return np.round(np.clip(blocks * 2.0, 0.0, 1.0) * LEVELS) / LEVELS


def changed_share(a: np.ndarray, b: np.ndarray) -> float:
    """The share of blocks of ``a`` and ``b`` (same shape) that differ by more than ``INK_STEP``
    from every block of the other within one block (either way)."""
    if a.shape != b.shape:
        return 1.0
    return float(np.mean(_unmatched(a, b) | _unmatched(b, a)))


def _unmatched(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    pad = np.pad(b, 1, mode="edge")
    rows, cols = a.shape
    best = np.full(a.shape, np.inf)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            best = np.minimum(best, np.abs(a - pad[dy:dy + rows, dx:dx + cols]))
    return best > INK_STEP


@dataclass(frozen=True)
class Pages:
    """A printed report's layout: its pages' ink maps and the headings on each page."""

    maps: list[np.ndarray]
    headings: list[list[str]]


def save(name: str, pages: Pages, folder: Path = DATA) -> None:
    """Write ``pages`` as the reference of run ``name`` into ``folder``: ``name.png`` (the ink
    maps side by side, ink dark) and its entry in ``pages.json``."""
    folder.mkdir(parents=True, exist_ok=True)
    sheet = 1.0 - np.concatenate(pages.maps, axis=1)
    mimage.imsave(folder / f"{name}.png", sheet, cmap="gray", vmin=0.0, vmax=1.0)
    index = folder / "pages.json"
    facts = json.loads(index.read_text(encoding="utf-8")) if index.exists() else {}
    facts[name] = {"pages": len(pages.maps), "block_grid": list(pages.maps[0].shape), "headings": pages.headings}
    index.write_text(json.dumps(facts, indent=1, ensure_ascii=False, sort_keys=True) + "\n", encoding="utf-8")


def load(name: str) -> Pages | None:
    """The reference of run ``name``, or None where none is kept."""
    index = DATA / "pages.json"
    if not index.exists() or not (DATA / f"{name}.png").exists():
        return None
    facts = json.loads(index.read_text(encoding="utf-8")).get(name)
    if facts is None:
        return None
    image = mimage.imread(str(DATA / f"{name}.png"))
    sheet = 1.0 - (image[..., 0] if image.ndim == 3 else image)
    sheet = np.round(sheet * LEVELS) / LEVELS
    cols = facts["block_grid"][1]
    maps = [sheet[:, i * cols:(i + 1) * cols] for i in range(facts["pages"])]
    return Pages(maps, facts["headings"])


def renderer() -> str:
    """What lays the pages out: Chromium's version and a digest of the installed fonts."""
    browser = next((b for b in ("chromium", "chromium-browser") if shutil.which(b)), None)
    version = (subprocess.run([browser, "--version"], capture_output=True, text=True).stdout.strip()
               if browser else "no chromium")
    fonts = (subprocess.run(["fc-list", ":", "family", "style"], capture_output=True, text=True).stdout
             if shutil.which("fc-list") else "")
    digest = hashlib.sha256("\n".join(sorted(fonts.splitlines())).encode()).hexdigest()[:16]
    return f"{version}; fonts {digest}"


def save_renderer(folder: Path = DATA) -> None:
    index = folder / "pages.json"
    facts = json.loads(index.read_text(encoding="utf-8")) if index.exists() else {}
    facts["_renderer"] = renderer()
    index.write_text(json.dumps(facts, indent=1, ensure_ascii=False, sort_keys=True) + "\n", encoding="utf-8")


def kept_renderer() -> str | None:
    index = DATA / "pages.json"
    return json.loads(index.read_text(encoding="utf-8")).get("_renderer") if index.exists() else None


def updating() -> bool:
    return os.environ.get(UPDATE_ENV, "") not in ("", "0")


def headings_per_page(pages: list[str], headings: list[str]) -> list[list[str]]:
    """The report's ``headings`` (h2, h3 text) found on each page's pdftotext text, in order. A
    heading matches a whole line, spaces ignored (pdftotext spaces out a heading's badge); a long
    one (a verdict badge wraps) a line of 10 characters or more that it begins with."""
    wanted = {"".join(h.split()): h.strip() for h in headings if h.strip()}
    found = []
    for text in pages:
        found.append([])
        for line in ("".join(ln.split()) for ln in text.splitlines()):
            match = wanted.get(line) or next((h for k, h in wanted.items() if len(k) > 25 and len(line) >= 10
                                              and k.startswith(line)), None)
            if match:
                found[-1].append(match)
    return found


def structure_problems(name: str, pages: Pages, kept: Pages, same_renderer: bool) -> list[str]:
    """What differs between a report as printed now and its reference: under any renderer its
    headings in order (every one printed, none lost or reordered) and its page count within one;
    under the references' own renderer its pages one by one (headings on each, ink maps)."""
    problems = []
    now_order = [h for page in pages.headings for h in page]
    kept_order = [h for page in kept.headings for h in page]
    if now_order != kept_order:
        lost = [h for h in kept_order if h not in now_order]
        new = [h for h in now_order if h not in kept_order]
        problems.append(f"{name}: the printed headings differ from the reference's (missing {lost}, new {new}"
                        f"{', reordered' if not lost and not new else ''})")
    slack = 0 if same_renderer else 1
    if abs(len(pages.maps) - len(kept.maps)) > slack:
        problems.append(f"{name}: {len(pages.maps)} pages, the reference has {len(kept.maps)}"
                        f"{'' if same_renderer else ' (one more or fewer is another renderer’s)'}")
    if not same_renderer:
        return problems
    for i, (now, then) in enumerate(zip(pages.headings, kept.headings), 1):
        if now != then:
            problems.append(f"{name} page {i}: headings {now}, the reference has {then}")
    for i, (now_map, then_map) in enumerate(zip(pages.maps, kept.maps), 1):
        share = changed_share(now_map, then_map)
        if share > MAX_CHANGED:
            problems.append(f"{name} page {i}: {share:.0%} of the page's blocks moved (at most {MAX_CHANGED:.0%})")
    return problems
