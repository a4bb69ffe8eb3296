"""Draws scripts/figure-plots' pictures from the measurements it made.

    figure_plots.py DATA_DIR OUT_DIR WHICH...

DATA_DIR holds what each measurement wrote (FIGURES_JSON of the scripts, eval's --json) and
the commit it was measured on (WHICH.commit); each picture's title says what it was measured
on, and its corner the commit.
"""

import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

data, out, which = sys.argv[1], sys.argv[2], sys.argv[3:]
BLUE, ORANGE, GREEN, GREY = "#1f77b4", "#ff7f0e", "#2ca02c", "#7f7f7f"


def load(name):
    with open(os.path.join(data, name)) as f:
        return json.load(f)


def percentile(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))] if values else float("nan")


def save(fig, name, measured):
    with open(os.path.join(data, f"{measured}.commit")) as f:
        commit = f.read().strip()
    fig.text(0.99, 0.01, f"mousepose {commit}", ha="right", va="bottom", fontsize=7, color=GREY)
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=110)
    plt.close(fig)
    print(f"figure-plots: wrote {os.path.join(out, name)}", file=sys.stderr)


def latency():
    """Each run's latencies (the two fast subscribers together) as a cumulative share."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    runs = [
        ("free.json", "colour camera running free", ORANGE),
        ("triggered.json", "colour camera triggered by the depth camera", BLUE),
        ("depth-only.json", "depth only", GREEN),
    ]
    longest = 0.0
    for name, label, colour in runs:
        run = load(name)
        values = sorted(run["latencies_ms"].get("fast-1", []) + run["latencies_ms"].get("fast-2", []))
        if not values:
            continue
        longest = max(longest, percentile(values, 0.999))
        share = [100.0 * (k + 1) / len(values) for k in range(len(values))]
        p50, p99 = percentile(values, 0.5), percentile(values, 0.99)
        ax.step(values, share, where="post", color=colour, label=f"{label}: p50 {p50:.1f} ms, p99 {p99:.1f} ms")
    ax.axvline(15.0, color=GREY, linestyle="--", linewidth=1)
    ax.text(15.3, 3, "goal: p99 < 15 ms", color=GREY, fontsize=8)
    ax.set_xlim(0, max(20.0, longest * 1.05))
    ax.set_ylim(0, 100)
    ax.set_xlabel("depth frame's arrival to the subscriber's receipt (ms)")
    ax.set_ylabel("messages received by then (%)")
    seconds = load("free.json").get("seconds", 0)
    ax.set_title(f"The live pose stream at 30 frames/s, fake cameras, {seconds:.0f} s a run", fontsize=11)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    save(fig, "latency.png", "latency")


def paws():
    """Recall and precision on real frames not learnt from, told the scale and not."""
    figures = load("paws.json")
    fig, ax = plt.subplots(figsize=(7, 4.2))
    groups = [("told_scale", "told the scale"), ("found_scale", "scale found")]
    width = 0.35
    for k, (key, label) in enumerate(groups):
        report = figures[key]
        values = [report["recall"], report["precision"]]
        bars = ax.bar([x + (k - 0.5) * width for x in range(2)], values, width, label=label,
                      color=[BLUE, ORANGE][k])
        ax.bar_label(bars, fmt="%.3f", fontsize=8)
    ax.axhline(0.9, color=GREY, linestyle="--", linewidth=1)
    ax.text(-0.45, 0.91, "goal 0.9", color=GREY, fontsize=8)
    ax.set_xticks(range(2), ["recall", "precision"])
    ax.set_ylim(0, 1.05)
    frames = len(figures.get("per_frame", []))
    ax.set_title(f"Paws on {frames} real bottom views not learnt from\n({figures['folds']} folds, "
                 f"each a {figures['detector']} learnt from the real frames alone)", fontsize=11)
    ax.legend(loc="lower right", fontsize=8)
    save(fig, "paws-real.png", "paws")


def flips():
    """Per stress group, the share of frames with head and tail swapped, three ways."""
    figures = load("flips.json")
    groups = list(figures["groups"])
    ways = [("flipped_forest", "the forest's votes alone", GREY),
            ("flipped_frame_alone", "each frame's own evidence", ORANGE),
            ("flipped_tracked", "after the tracker", BLUE)]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.27
    for k, (key, label, colour) in enumerate(ways):
        shares = [100.0 * g[key] / max(g["frames"], 1) for g in figures["groups"].values()]
        bars = ax.bar([x + (k - 1) * width for x in range(len(groups))], shares, width, label=label, color=colour)
        ax.bar_label(bars, fmt="%.1f", fontsize=7)
    ax.axhline(2.0, color=GREY, linestyle="--", linewidth=1)
    ax.text(len(groups) - 0.5, 2.1, "goal <= 2 %", color=GREY, fontsize=8, ha="right")
    ax.set_xticks(range(len(groups)), groups)
    ax.set_ylabel("frames with head and tail swapped (%)")
    frames = sum(g["frames"] for g in figures["groups"].values())
    ax.set_title(f"Head and tail swapped, {figures['sessions']} rendered sessions a group, {frames} frames",
                 fontsize=11)
    ax.legend(fontsize=8)
    save(fig, "flips.png", "flips")


def moseq2():
    """Wall time and peak memory of both tools on the same recording, every round."""
    figures = load("moseq2.json")
    tools = ["moseq2-extract", "mousepose"]
    fig, (time_ax, memory_ax) = plt.subplots(1, 2, figsize=(9, 4))
    for ax, index, label in [(time_ax, 0, "wall time (s)"), (memory_ax, 1, "peak memory (MB)")]:
        # As moseq2-check says them: the median wall time, the largest peak memory.
        pick = (lambda v: sorted(v)[len(v) // 2]) if index == 0 else max
        values = [pick([r[index] for r in figures["rounds"][t]]) for t in tools]
        bars = ax.bar(tools, values, color=[GREY, BLUE])
        ax.bar_label(bars, fmt="%.1f" if index == 0 else "%.0f", fontsize=8)
        ax.set_ylabel(label)
        ratio = values[0] / values[1]
        ax.set_title(f"{['median wall time', 'largest peak memory'][index]}: {ratio:.1f}x less", fontsize=10)
    fig.suptitle(f"Extracting {figures['frames']} depth frames of 512x424 (renders), whole processes, "
                 f"{len(figures['rounds']['mousepose'])} rounds taking turns", fontsize=11)
    save(fig, "moseq2.png", "moseq2")


for name in which:
    {"latency": latency, "paws": paws, "flips": flips, "moseq2": moseq2}[name]()
