"""The faults of a soak, drawn from a seed so that every pair of them overlaps at least once.

    soak-schedule.py SEED SECONDS [--short]

Prints one episode a line, as JSON, earliest first: {"kinds": [...], "not_before": s, "lead":
s, "actions": [[s, action], ...]}. An episode's faults overlap at its moment T: an action's time
is seconds from T (negative: before it). T is `not_before`, or for an episode with a
`rotation` the first chunk boundary at least `lead` seconds after it, which only the run knows
(the daemon begins a chunk a period after the last began, and a full disk begins one early):
the executor finds it. On stderr: the seed, each episode and the pairs the schedule covers.
Exits 1 when SECONDS cannot hold every pair once.

The seven kinds of fault, each pair of which must meet:
  disk-full    the disk filled, then freed (an interval)
  colour-kill  the colour camera's process killed, then started again (an interval)
  depth-stall  the depth camera silent past the stall time: taken for gone, reopened
  camera-gap   the depth camera silent for less than the stall time: frames skipped, a gap in
               its numbers
  rotation     a chunk boundary (the daemon's own)
  sighup       SIGHUP to the daemon
  dir-move     the run directory renamed away; the moved copy removed at the episode's end
Three to an episode, on the lines of a Fano plane: seven episodes hold every pair exactly once.
The seed labels the plane's points and orders its lines; while the run has time, the plane is
drawn again with another labelling, so an hour meets every pair several times. `--short` is the
test suite's version: one plane, faults of a few seconds.
"""

import itertools
import json
import random
import sys

KINDS = ["disk-full", "colour-kill", "depth-stall", "camera-gap", "rotation", "sighup", "dir-move"]
FANO = [(0, 1, 3), (1, 2, 4), (2, 3, 5), (3, 4, 6), (4, 5, 0), (5, 6, 1), (6, 0, 2)]
# Seconds each interval lasts, and the pause after an episode for the rig to settle: an hour's
# and the suite's.
LONG = {"disk-full": 60, "colour-kill": 30, "depth-stall": 20, "camera-gap": 1, "settle": 30}
# The suite's daemon takes a camera silent for a second for gone: its gap is half of one.
SHORT = {"disk-full": 4, "colour-kill": 3, "depth-stall": 3, "camera-gap": 0.5, "settle": 3}
# What starts and ends each interval.
INTERVALS = {
    "disk-full": ("disk-fill", "disk-free"),
    "colour-kill": ("colour-kill", "colour-start"),
    "depth-stall": ("depth-stall", "depth-go"),
    "camera-gap": ("depth-stall", "depth-go"),
}


def episode(kinds, rng, length):
    """An episode's actions around its moment T: each interval begins a random share of its
    length before T (at least a second) and ends after it; instants at T."""
    actions = []
    lead = 0
    for kind in kinds:
        if kind == "camera-gap" and "depth-stall" in kinds:
            # One camera: its gap comes as it is back from the stall, a second after.
            continue
        if kind in INTERVALS:
            d = length[kind]
            before = max(1, round(d * rng.uniform(0.25, 0.75))) if d > 1 else 0
            if kind == "depth-stall" and "camera-gap" in kinds:
                # Back at T, where the other faults are, and its gap a second after.
                before = d
            start, end = INTERVALS[kind]
            actions += [[-before, start], [d - before, end]]
            lead = max(lead, before)
        elif kind == "sighup":
            actions.append([0, "sighup"])
        elif kind == "dir-move":
            actions.append([0, "dir-move"])
    if "camera-gap" in kinds and "depth-stall" in kinds:
        back = next(t for t, what in actions if what == "depth-go")
        actions += [[back + 1, "depth-stall"], [back + 1 + length["camera-gap"], "depth-go"]]
    # The moved copy is removed once the episode's intervals are over.
    last = max((t for t, _ in actions), default=0)
    if "dir-move" in kinds:
        actions.append([last + 1, "dir-remove"])
    actions.sort(key=lambda a: a[0])
    return actions, lead


def overlapping(kinds_at):
    """The pairs of kinds that meet (active at once, or one within a second of the other):
    intervals by their span, instants as a second."""
    pairs = set()
    for spans in kinds_at:
        for (a, sa), (b, sb) in itertools.combinations(spans, 2):
            if a != b and sa[0] <= sb[1] + 1 and sb[0] <= sa[1] + 1:
                pairs.add(tuple(sorted((a, b))))
    return pairs


def main():
    args = [a for a in sys.argv[1:] if a != "--short"]
    if len(args) != 2 or not all(a.isdigit() for a in args):
        sys.exit("usage: soak-schedule.py SEED SECONDS [--short]")
    seed, seconds = int(args[0]), int(args[1])
    short = "--short" in sys.argv
    length = SHORT if short else LONG
    rng = random.Random(seed)
    episodes, spans, t = [], [], length["settle"]
    for plane in itertools.count():
        labels = KINDS[:]
        rng.shuffle(labels)
        lines = FANO[:]
        rng.shuffle(lines)
        drawn = []
        for line in lines:
            kinds = sorted(labels[k] for k in line)
            actions, lead = episode(kinds, rng, length)
            span = max(a[0] for a in actions) + lead
            drawn.append(({"kinds": kinds, "not_before": t, "lead": lead, "actions": actions}, span))
            t += span + length["settle"]
        if t > seconds and plane > 0:
            break
        if t > seconds:
            print(f"{seconds} s cannot hold one of each pair: the schedule needs {t} s", file=sys.stderr)
            sys.exit(1)
        for e, _ in drawn:
            episodes.append(e)
            # What is active around T (a rotation is taken as the second at T).
            at = []
            for kind in e["kinds"]:
                if kind in INTERVALS:
                    start, end = INTERVALS[kind]
                    # The camera's gap is its last stall, when it has two.
                    begin = [a[0] for a in e["actions"] if a[1] == start][-1 if kind == "camera-gap" else 0]
                    stop = next(a[0] for a in e["actions"] if a[1] == end and a[0] > begin)
                    at.append((kind, (begin, stop)))
                else:
                    at.append((kind, (0, 1)))
            spans.append(at)
        if short:
            break
    pairs = overlapping(spans)
    missing = [p for p in itertools.combinations(sorted(KINDS), 2) if p not in pairs]
    print(f"seed {seed}: {len(episodes)} episodes, {len(pairs)} of 21 pairs", file=sys.stderr)
    for e in episodes:
        print(f"  from {e['not_before']} s: {' + '.join(e['kinds'])}", file=sys.stderr)
    if len(pairs) < 21:
        sys.exit(f"only {len(pairs)} of the 21 pairs meet: not {missing}")
    for e in episodes:
        print(json.dumps(e))


main()
