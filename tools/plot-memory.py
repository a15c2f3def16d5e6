#!/usr/bin/env python3
"""Plots tarmac-map --memory-log files (resident memory against distance driven) as an SVG.

Usage: tools/plot-memory.py OUT.svg LABEL=FILE.csv [LABEL=FILE.csv ...]

Each CSV has the columns scan, distance_m, rss_mib, tsdf_resident_mib, tile_store_mib; the plot
draws RSS (solid) and the TSDF as counted against tsdf.resident_limit_mb (dashed) per file, and
the tile store of the last file (dotted). Standard library only (no matplotlib on the target).
"""
import csv
import sys

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"]
W, H, L, R, T, B = 760, 420, 70, 20, 30, 50


def read(path, most=500):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    rows = [{k: float(v) for k, v in r.items()} for r in rows]
    if len(rows) <= most:
        return rows
    # Thinned to `most` points, keeping each stretch's highest RSS (the peaks are the point).
    step = len(rows) / most
    out = []
    for i in range(most):
        chunk = rows[int(i * step):int((i + 1) * step)] or rows[-1:]
        out.append(max(chunk, key=lambda r: r["rss_mib"]))
    return out


def nice_step(span, ticks=6):
    raw = span / ticks
    for m in (1, 2, 5, 10):
        step = m * 10 ** len(str(int(raw))) / 10
        if step >= raw:
            return step
    return raw


def main(argv):
    if len(argv) < 3:
        print(__doc__)
        return 2
    out, series = argv[1], []
    for arg in argv[2:]:
        label, _, path = arg.partition("=")
        series.append((label, read(path)))
    xmax = max(r["distance_m"] for _, rows in series for r in rows) or 1.0
    ymax = max(max(r["rss_mib"], r["tsdf_resident_mib"], r["tile_store_mib"])
               for _, rows in series for r in rows) or 1.0
    xs, ys = nice_step(xmax), nice_step(ymax)
    xmax = xs * (int(xmax / xs) + 1)
    ymax = ys * (int(ymax / ys) + 1)

    def px(x):
        return L + (W - L - R) * x / xmax

    def py(y):
        return H - B - (H - T - B) * y / ymax

    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           'font-family="sans-serif" font-size="12">',
           f'<rect width="{W}" height="{H}" fill="white"/>']
    for i in range(int(xmax / xs) + 1):
        x = px(i * xs)
        svg.append(f'<line x1="{x:.1f}" y1="{T}" x2="{x:.1f}" y2="{H - B}" stroke="#ddd"/>')
        svg.append(f'<text x="{x:.1f}" y="{H - B + 16}" text-anchor="middle">{i * xs:g}</text>')
    for i in range(int(ymax / ys) + 1):
        y = py(i * ys)
        svg.append(f'<line x1="{L}" y1="{y:.1f}" x2="{W - R}" y2="{y:.1f}" stroke="#ddd"/>')
        svg.append(f'<text x="{L - 6}" y="{y + 4:.1f}" text-anchor="end">{i * ys:g}</text>')
    svg.append(f'<text x="{(L + W - R) / 2}" y="{H - 12}" text-anchor="middle">'
               'distance driven, m</text>')
    svg.append(f'<text x="16" y="{(T + H - B) / 2}" text-anchor="middle" '
               f'transform="rotate(-90 16 {(T + H - B) / 2})">MiB</text>')

    def line(rows, key, colour, dash):
        pts = " ".join(f"{px(r['distance_m']):.1f},{py(r[key]):.1f}" for r in rows)
        extra = f' stroke-dasharray="{dash}"' if dash else ""
        svg.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" '
                   f'stroke-width="1.5"{extra}/>')

    legend = []
    for i, (label, rows) in enumerate(series):
        c = COLOURS[i % len(COLOURS)]
        line(rows, "rss_mib", c, None)
        line(rows, "tsdf_resident_mib", c, "6 3")
        legend += [(f"{label}: RSS", c, None), (f"{label}: TSDF resident", c, "6 3")]
    line(series[-1][1], "tile_store_mib", "#555", "2 3")
    legend.append((f"{series[-1][0]}: tile store on disk", "#555", "2 3"))
    for i, (text, c, dash) in enumerate(legend):
        y = T + 8 + 16 * i
        extra = f' stroke-dasharray="{dash}"' if dash else ""
        svg.append(f'<line x1="{L + 12}" y1="{y}" x2="{L + 42}" y2="{y}" stroke="{c}" '
                   f'stroke-width="1.5"{extra}/>')
        svg.append(f'<text x="{L + 48}" y="{y + 4}">{text}</text>')
    svg.append("</svg>")
    with open(out, "w") as f:
        f.write("\n".join(svg) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
