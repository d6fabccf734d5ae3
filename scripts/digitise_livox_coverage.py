"""Read Livox's published FoV-coverage curves off the wiki's figures, pixel by pixel.

Source: repository ``Livox-SDK/livox_wiki_en`` (commit af2bea9 read here), page
``source/introduction/Point_Cloud_Characteristics_and_Coordinate_System .rst`` (a space before
``.rst``), figures ``source/image/Mid-40_FOV_coverage.png``, ``Horizon_FOV_change.png`` and
``tele_coverage.png``.  The figures carry no licence, so they are not copied into this repository:
fetch the wiki and point this script at its git directory or at a folder holding the three PNGs.

How each curve is read (all in this file, nothing by eye):

1. Axes: the y axis from its 11 tick marks (0, 10, ..., 100 %), each found as the darkness-weighted
   centre of its dark run just inside the left frame line, then a least-squares line through them
   (residuals printed, all under 0.3 px).  The x axis from the vertical grid lines and frame lines
   (pixel columns listed in ``FIGURES``, each read off the image: the columns where the dotted
   grid-line grey or the frame's dark grey fills the plot's height).
2. The curve: its grey level (the solid Livox curve is drawn in one flat grey: 192 on the Horizon
   and Tele-15 figures, 209 on the Mid-40's), pixel runs of that grey in each column.  The dotted
   multi-line comparison ramps (0 s -> 0.1 s) in the same grey touch the curve near the origin; their
   straight centre lines (from the origin to the plateau's first dash) are masked 4.5 px either
   side, and a column whose run touches the mask is not used.  Where the curve meets the top frame
   line (the 100 % plateau) its upper edge is hidden; the centre is then the lower edge less half the
   stroke's vertical chord.
3. The curve's centre in each usable column is the middle of its run; the value at a published time
   is a least-squares quadratic through the usable column centres within +-6 px of that time's
   column.
4. Precision (the ``plus_minus`` column): 1 px of stroke centre in y, plus the x calibration's
   0.5 px times the local slope, plus the fit's residual; 0.3 to 2 points of coverage.

Writes ``sim/scan/data/livox_coverage_{mid40,horizon,tele15}.csv`` (comment lines name the source
and the method) and prints the tables.

Usage: python scripts/digitise_livox_coverage.py WIKI_GIT_DIR_OR_PNG_FOLDER
(e.g. the ``fetch`` mirror of github:Livox-SDK/livox_wiki_en).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np

DATA_DIR = Path(__file__).resolve().parents[1] / "sim" / "scan" / "data"


@dataclass(frozen=True)
class Figure:
    preset: str
    png: str
    x_cal: tuple[tuple[float, float], ...]   # (time [s], pixel column) of grid / frame lines
    curve_grey: tuple[int, int]              # the solid curve's grey level band (core pixels)
    ramps_px: tuple[tuple[float, float, float, float], ...]  # dotted ramps to mask: x0, y0, x1, y1
    times_s: tuple[float, ...]               # where to read the curve
    plateau_s: float                         # the curve is flat (within 1 point) from here on
    stroke_px: float                         # the curve's stroke width across its direction


FIGURES = (
    Figure("mid40", "Mid-40_FOV_coverage.png",
           # frame lines at 94.5 (0 s) / 782.5 (1.4 s); dotted grid columns 144, 193, 242, 291, 389, 439,
           # 488, 586, 684 at 0.1 ... 1.2 s
           x_cal=((0.0, 94.5), (0.1, 144), (0.2, 193), (0.3, 242), (0.4, 291), (0.6, 389), (0.7, 439),
                  (0.8, 488), (1.0, 586), (1.2, 684), (1.4, 782.5)),
           curve_grey=(208, 213),
           ramps_px=(),  # the 64-line ramp is grey 192, not the curve's 209: no mask needed
           times_s=tuple(round(0.05 * i, 2) for i in range(1, 29)), plateau_s=1.4, stroke_px=5.0),
    Figure("horizon", "Horizon_FOV_change.png",
           # frame lines 108 (0 s), 817 (0.8 s); dotted grid columns 285, 463, 551, 640 at 0.2, 0.4, 0.5, 0.6 s
           x_cal=((0.0, 108), (0.2, 285), (0.4, 463), (0.5, 551), (0.6, 640), (0.8, 817)),
           curve_grey=(180, 206),
           # the 64-line ramp, same grey as the curve: origin to its plateau's first dash (row 167.5)
           ramps_px=((107.6, 470.6, 196.3, 167.5),),
           times_s=tuple(round(0.05 * i, 2) for i in range(1, 16)), plateau_s=0.6, stroke_px=5.0),
    Figure("tele15", "tele_coverage.png",
           # frame line 110 (0 s); x-axis ticks at 286.5, 463.5, 640.5, 817.5 (0.1 ... 0.4 s); dotted grid
           # columns 198, 375, 552, 729 at 0.05, 0.15, 0.25, 0.35 s
           x_cal=((0.05, 198), (0.1, 286.5), (0.15, 375), (0.2, 463.5), (0.25, 552), (0.3, 640.5), (0.35, 729),
                  (0.4, 817.5)),
           curve_grey=(180, 206),
           # the 128-line (plateau row 53) and 64-line (row 162) ramps, same grey as the curve
           ramps_px=((109.5, 463.7, 286.5, 53.0), (109.5, 463.7, 286.5, 162.0)),
           times_s=tuple(round(0.01 * i, 2) for i in range(1, 21)) + (0.25, 0.3, 0.35),
           plateau_s=0.13, stroke_px=5.0),
)


def load_png(source: Path, name: str) -> np.ndarray:
    """The figure as an (h, w, 3) array of 0-255 grey levels, from a folder or the wiki's git dir."""
    if (source / name).is_file():
        path = source / name
    else:
        path = Path("/tmp") / f"livox_wiki_{name}"
        blob = subprocess.run(["git", f"--git-dir={source}", "show", f"HEAD:source/image/{name}"],
                              check=True, capture_output=True).stdout
        path.write_bytes(blob)
    return (mpimg.imread(path)[..., :3] * 255).round()


def y_axis(img: np.ndarray, frame_col: int) -> tuple[float, float, float]:
    """(row of 0 %, rows per %, worst tick residual [px]) from the tick marks inside the frame."""
    col = 235 - img[:, frame_col + 3, 0]
    col[col < 60] = 0
    rows = np.flatnonzero(col)
    groups = np.split(rows, np.flatnonzero(np.diff(rows) > 2) + 1)
    centres = np.array([(g * col[g]).sum() / col[g].sum() for g in groups])
    # 100 ... 10 %: the 0 % tick lies on the bottom frame line, under the curve's start
    centres = np.sort(centres)[:10]          # below the plot come the tick labels
    levels = np.arange(100, 0, -10)
    slope, intercept = np.polyfit(levels, centres, 1)
    resid = np.abs(centres - (slope * levels + intercept)).max()
    return intercept, -slope, resid


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    groups = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    return [(int(g[0]), int(g[-1])) for g in groups]


def curve_centres(img, fig: Figure, x_first: int, x_last: int, frame_top: float,
                  skip_cols: set[int] = frozenset()) -> dict[int, float]:
    """Row of the curve's centre line in every usable column, traced from the plateau leftward."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    lo, hi = fig.curve_grey
    curve = (r >= lo) & (r <= hi) & (np.abs(r - g) <= 4) & (np.abs(r - b) <= 12)
    rows, cols = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    masked = np.zeros_like(curve)
    for x0, y0, x1, y1 in fig.ramps_px:
        # distance to the ramp's centre segment
        dx, dy = x1 - x0, y1 - y0
        t = np.clip(((cols - x0) * dx + (rows - y0) * dy) / (dx * dx + dy * dy), 0, 1)
        masked |= np.hypot(cols - x0 - t * dx, rows - y0 - t * dy) <= 4.5
    # an edge is hidden where something darker than the curve (a dark dash, a tick, the frame) or a
    # masked ramp lies within 2 px beyond it: anti-aliasing only ever blends the curve toward white
    occluder = ((r < lo - 2) & (np.abs(r - g) <= 4)) | masked
    n_rows = img.shape[0]
    centres: dict[int, float] = {}
    prev, slope, history = None, 0.0, []
    for x in range(x_last, x_first - 1, -1):
        if x in skip_cols:                  # a dotted grid line in the curve's grey
            continue
        candidates = [run for run in runs(curve[:, x] & ~masked[:, x]) if run[1] > frame_top - 3]
        if prev is not None:
            pred = prev + slope
            window = 6 + 2 * abs(slope)
            candidates = [run for run in candidates if run[0] - window <= pred <= run[1] + window]
        else:                               # start on the plateau, just under the top frame line
            candidates = [run for run in candidates if run[0] <= frame_top + 12]
        if not candidates:
            if prev is not None:            # hidden behind a dash: continue the line
                prev += slope
                history.append((x, prev))
            continue
        if prev is None:
            top, bottom = min(candidates, key=lambda run: run[0])
        else:
            top, bottom = min(candidates, key=lambda run: 0 if run[0] - 2 <= pred <= run[1] + 2
                              else min(abs(run[0] - pred), abs(run[1] - pred)))
        chord = fig.stroke_px * np.hypot(1.0, slope)
        top_hidden = top <= frame_top + 1.5 or occluder[max(top - 2, 0):top, x].any()
        bottom_hidden = occluder[bottom + 1:min(bottom + 3, n_rows), x].any()
        if top_hidden and bottom_hidden or bottom - top + 1 > chord + 2.5:
            centre = None                   # both edges cut, or merged with a dash: not used
        elif top_hidden:                    # under the frame line, a dash or a masked ramp: the lower edge
            centre = bottom - (chord - 1) / 2
        elif bottom_hidden:
            centre = top + (chord - 1) / 2
        else:
            centre = (top + bottom) / 2
        # an unusable column continues the line from the columns before it
        guess = centre if centre is not None else (prev + slope if prev is not None else (top + bottom) / 2)
        history.append((x, guess))
        if len(history) >= 6:
            slope = (history[-1][1] - history[-6][1]) / (history[-6][0] - history[-1][0])
        prev = guess
        if centre is not None:
            centres[x] = centre
    return centres


def digitise(fig: Figure, source: Path, check_ax=None) -> list[tuple[float, float, float]]:
    img = load_png(source, fig.png)
    t_cal, x_cal = np.array(fig.x_cal).T
    px_per_s, x_zero = np.polyfit(t_cal, x_cal, 1)
    x_resid = np.abs(x_cal - (px_per_s * t_cal + x_zero)).max()
    frame_col = int(round(x_zero))
    y_zero, px_per_pct, y_resid = y_axis(img, frame_col)
    frame_top = y_zero - 100 * px_per_pct
    print(f"{fig.preset}: x 0 s at {x_zero:.2f} px, {px_per_s:.2f} px/s (worst residual {x_resid:.2f} px); "
          f"y 0 % at {y_zero:.2f} px, {px_per_pct:.3f} px/% (worst tick residual {y_resid:.2f} px)")
    x_last = int(round(x_zero + px_per_s * max(t_cal))) - 2  # inside the right frame line
    grid_cols = {int(round(c)) + d for c in x_cal for d in (-1, 0, 1)}
    centres = curve_centres(img, fig, frame_col + 2, x_last, frame_top, grid_cols)
    xs = np.array(sorted(centres))
    ys = np.array([centres[x] for x in xs])
    out = []
    for t in fig.times_s:
        xt = x_zero + px_per_s * t
        near = np.abs(xs - xt) <= 6
        if near.sum() < 4:
            raise SystemExit(f"{fig.preset}: only {near.sum()} usable columns near t = {t} s")
        coef = np.polyfit(xs[near] - xt, ys[near], 2)
        fit_resid = np.sqrt(np.mean((np.polyval(coef, xs[near] - xt) - ys[near]) ** 2))
        y = coef[2]
        value = (y_zero - y) / px_per_pct
        slope_pct_per_px = abs(coef[1]) / px_per_pct
        plus_minus = (1.0 + fit_resid) / px_per_pct + 0.5 * slope_pct_per_px
        out.append((t, min(value, 100.0), plus_minus))
    if check_ax is not None:                # the traced centre line and the read values over the figure
        check_ax.imshow(img / 255, interpolation="nearest")
        check_ax.plot(xs, ys, ",", color="red")
        check_ax.plot([x_zero + px_per_s * t for t, _, _ in out], [y_zero - v * px_per_pct for _, v, _ in out],
                      "+", color="blue", ms=8)
        check_ax.set_title(f"{fig.preset}: traced centre (red), read values (blue)")
    return out


def write_csv(fig: Figure, rows, commit: str) -> Path:
    path = DATA_DIR / f"livox_coverage_{fig.preset}.csv"
    lines = [
        f"# Livox {fig.preset}: FoV coverage against integration time, read off the Livox wiki's figure",
        f"# Livox-SDK/livox_wiki_en {commit} source/image/{fig.png} by scripts/digitise_livox_coverage.py",
        "# (axes from the tick marks and grid lines, the curve's flat grey followed column by column,",
        "# a quadratic through the column centres within +-6 px; plus_minus: 1 px of stroke centre plus",
        "# 0.5 px of x calibration times the slope plus the fit residual). coverage = illuminated area / FoV.",
        f"# plateau_s = {fig.plateau_s}: the curve is flat (within 1 point) from there on",
        "time_s,coverage_pct,plus_minus_pct",
    ]
    lines += [f"{t:g},{v:.1f},{pm:.1f}" for t, v, pm in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", type=Path, help="the livox_wiki_en git directory, or a folder with the PNGs")
    ap.add_argument("--check", metavar="F.png", help="draw the traced curves over the figures, to look at")
    args = ap.parse_args(argv)
    axes = [None] * len(FIGURES)
    if args.check:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        check_fig, axes = plt.subplots(len(FIGURES), 1, figsize=(10, 6.5 * len(FIGURES)))
    commit = "(folder)"
    if not (args.source / FIGURES[0].png).is_file():
        commit = subprocess.run(["git", f"--git-dir={args.source}", "rev-parse", "--short", "HEAD"],
                                check=True, capture_output=True, text=True).stdout.strip()
    for fig, ax in zip(FIGURES, axes):
        rows = digitise(fig, args.source, ax)
        path = write_csv(fig, rows, commit)
        print("  " + "  ".join(f"{t:g}s {v:.1f}+-{pm:.1f}" for t, v, pm in rows))
        print(f"  -> {path.relative_to(DATA_DIR.parents[2])}")
    if args.check:
        check_fig.tight_layout()
        check_fig.savefig(args.check, dpi=110)
        print(f"check plot: {args.check}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
