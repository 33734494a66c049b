#!/usr/bin/env python3
"""Accuracy table of the single-corner benchmark (the paper's section IV-A protocols).

Usage: report.py DIR [--markdown]

Reads DIR/manifest.jsonl (truth, CRB per image), DIR/ours.jsonl (conic-corners' variants) and
DIR/peers.jsonl (bench/peers.py); either result file may be missing. For every protocol and
sweep value it prints one row:
  value | CRB (mean over the images that have one) | per method: MLE (SR %) | ratio
where, as in the paper, a localization succeeds when its error |x - x_gt| <= 1 px, MLE is the mean
error over the successful images (px) and SR the share of successful images among all images of
that row (a missing result or found = false is a failure). `ratio` is conic-corners' MLE over the
smallest MLE among the peers (named in `best peer`). The opencv-csp-w* peers start from the
rounded truth, so they measure a refiner with an oracle start, not a detector.
Methods are columns in a fixed order: "conic-corners", our other variants (sorted), the peers in
bench/peers.py's order, then unknown methods (sorted); methods absent from a protocol are skipped.
A last table gives each method's mean run time per image where the result lines carry "ms".
"""
import argparse
import json
import math
import os
import signal
import sys
from collections import defaultdict

OURS_PRIMARY = "conic-corners"
from peers import METHODS as PEER_ORDER  # noqa: E402  (bench/ is on sys.path: run as a script)
PROTOCOL_ORDER = ("noise", "blur", "perspective", "curvature")
SUCCESS_PX = 1.0


def read_jsonl(path, required=True):
    if not os.path.exists(path):
        if required:
            sys.exit(f"report: {path} not found")
        print(f"report: {path} not found, skipped", file=sys.stderr)
        return []
    rows = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if line:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError as e:
                    sys.exit(f"report: {path}:{n}: {e}")
    return rows


def method_order(ours, peers):
    first = [OURS_PRIMARY] if OURS_PRIMARY in ours else []
    order = first + sorted(ours - set(first))
    order += [m for m in PEER_ORDER if m in peers]
    order += sorted(peers - set(order))
    return order


def fmt_value(v):
    return f"{v:g}" if isinstance(v, (int, float)) else str(v)


def summarize(root):
    """Rows per protocol: list of (protocol, methods, rows), plus the run-time table."""
    manifest = read_jsonl(os.path.join(root, "manifest.jsonl"))
    ours_rows = read_jsonl(os.path.join(root, "ours.jsonl"), required=False)
    peer_rows = read_jsonl(os.path.join(root, "peers.jsonl"), required=False)
    ours = {r["method"] for r in ours_rows}
    peers = {r["method"] for r in peer_rows} - ours
    methods = method_order(ours, peers)

    result = {}
    ms = defaultdict(list)
    for r in ours_rows + peer_rows:
        result[(r["image"], r["method"])] = r
        if isinstance(r.get("ms"), (int, float)):
            ms[r["method"]].append(r["ms"])

    groups = defaultdict(lambda: defaultdict(list))
    for e in manifest:
        groups[e.get("protocol", "?")][e.get("value")].append(e)
    protocols = [p for p in PROTOCOL_ORDER if p in groups]
    protocols += sorted(set(groups) - set(protocols))

    tables = []
    for proto in protocols:
        images = {e["image"] for vals in groups[proto].values() for e in vals}
        present = [m for m in methods if any((im, m) in result for im in images)]
        ours_here = [m for m in present if m in ours]
        primary = ours_here[0] if ours_here else None
        rows = []
        for value in sorted(groups[proto], key=lambda v: (not isinstance(v, (int, float)), v)):
            entries = groups[proto][value]
            crbs = [e["crb"] for e in entries if isinstance(e.get("crb"), (int, float))]
            stats = {}
            for m in present:
                errs = []
                for e in entries:
                    r = result.get((e["image"], m))
                    if r and r.get("found") and r.get("x") is not None and r.get("y") is not None:
                        err = math.hypot(r["x"] - e["truth"][0], r["y"] - e["truth"][1])
                        if err <= SUCCESS_PX:
                            errs.append(err)
                mle = sum(errs) / len(errs) if errs else None
                stats[m] = (mle, 100.0 * len(errs) / len(entries))
            peer_mles = [(stats[m][0], m) for m in present
                         if m in peers and stats[m][0] is not None]
            best = min(peer_mles) if peer_mles else None
            ratio = None
            if best and primary and stats[primary][0] is not None and best[0] > 0:
                ratio = stats[primary][0] / best[0]
            rows.append({
                "value": value,
                "n": len(entries),
                "crb": sum(crbs) / len(crbs) if crbs else None,
                "stats": stats,
                "ratio": ratio,
                "best": best[1] if best else None,
            })
        tables.append((proto, present, primary, rows))
    runtime = [(m, sum(ms[m]) / len(ms[m]), len(ms[m])) for m in methods if ms[m]]
    return tables, runtime


def cell(stat):
    mle, sr = stat
    return f"{'-' if mle is None else f'{mle:.4f}'} ({sr:.0f}%)"


def render(tables, runtime, markdown):
    out = []
    for proto, present, primary, rows in tables:
        head = ["value", "n", "CRB"] + present + [
            f"ratio {primary}/best peer" if primary else "ratio", "best peer"]
        body = []
        for r in rows:
            body.append([fmt_value(r["value"]), str(r["n"]),
                         "-" if r["crb"] is None else f"{r['crb']:.4f}"]
                        + [cell(r["stats"][m]) for m in present]
                        + ["-" if r["ratio"] is None else f"{r['ratio']:.2f}", r["best"] or "-"])
        out.append(f"### {proto}" if markdown else f"== {proto} ==  (cells: MLE px (SR %), "
                   f"success = error <= {SUCCESS_PX:g} px)")
        out += table(head, body, markdown)
        out.append("")
    if runtime:
        out.append("### run time" if markdown else "== run time ==")
        out += table(["method", "mean ms / image", "images"],
                     [[m, f"{t:.2f}", str(n)] for m, t, n in runtime], markdown)
    return "\n".join(out)


def table(head, body, markdown):
    if markdown:
        lines = ["| " + " | ".join(head) + " |",
                 "|" + "|".join("---:" if i < 3 else "---" for i in range(len(head))) + "|"]
        lines += ["| " + " | ".join(row) + " |" for row in body]
        return lines
    widths = [max(len(x) for x in col) for col in zip(head, *body)]

    def fmt(row):
        return "  ".join(x.rjust(w) for x, w in zip(row, widths))

    return [fmt(head), fmt(["-" * w for w in widths])] + [fmt(row) for row in body]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("dir")
    ap.add_argument("--markdown", action="store_true", help="markdown tables for BENCHMARKS.md")
    a = ap.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `report.py DIR | head` ends quietly
    tables, runtime = summarize(a.dir)
    print(render(tables, runtime, a.markdown))


if __name__ == "__main__":
    main()
