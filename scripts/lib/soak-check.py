"""The verdict of scripts/soak on a finished run: every frame accounted for, every chunk closed
and replayed whole, what the report calls recorded on the disk, no counter of /metrics ever
fallen. Prints the figures; exits 3 when any check fails.

    soak-check.py REPORT.json OUT_DIR REPLAYED_DIR SCRAPES_DIR
"""

import json
import pathlib
import re
import sys

report_path, out, replayed, scrapes = (pathlib.Path(a) for a in sys.argv[1:5])
failures = []


def fail(what):
    failures.append(what)
    print("FAILED:", what)


report = json.loads(report_path.read_text())
cameras = report["cameras"]
for name, c in sorted(cameras.items()):
    processed = c["paired"] + c["unpaired"] + c["dropped_total"]
    recorded = c.get("recorded", 0) + c["not_recorded_total"]
    if c["captured"] != processed:
        fail(f"{name}: captured {c['captured']} but paired + unpaired + dropped {processed}")
    if c["captured"] != recorded:
        fail(f"{name}: captured {c['captured']} but recorded + not recorded {recorded}")
    outages = c.get("outages", [])
    if any(o.get("end_ns") is None for o in outages):
        fail(f"{name}: an outage never ended")
    print(
        f"{name}: captured {c['captured']}, paired {c['paired']}, unpaired {c['unpaired']}, "
        f"dropped {c['dropped']}, recorded {c.get('recorded')}, not recorded {c.get('not_recorded')}, "
        f"lost after recording {c.get('lost_after_recording', {})}, outages {len(outages)}"
    )

chunks = sorted(out.glob("*/chunk-*"))
on_disk = {"depth": 0, "color": 0}
replay_drops = 0
poses_only = 0
for chunk in chunks:
    if sorted(p.name for p in chunk.iterdir()) == ["poses.csv", "poses_raw.csv", "summary.json"]:
        # Its whole time the disk was full: its poses, no session (its frames not recorded).
        poses_only += 1
        continue
    for f in ("session.toml", "poses.csv", "summary.json", "events.jsonl"):
        if not (chunk / f).is_file():
            fail(f"{chunk.name} has no {f}")
    events = (chunk / "events.jsonl").read_text() if (chunk / "events.jsonl").is_file() else ""
    if '"session_ended"' not in events:
        fail(f"{chunk.name} was not closed (no session_ended)")
    frames = {}
    for name in on_disk:
        stamps = chunk / name / "timestamps.csv"
        frames[name] = sum(1 for _ in open(stamps)) - 1 if stamps.is_file() else 0
        on_disk[name] += frames[name]
    if frames["depth"] == 0:
        # Colour frames only (the depth camera away for the chunk's time): nothing to replay.
        continue
    summary = replayed / chunk.name / "summary.json"
    if not summary.is_file():
        fail(f"{chunk.name} did not replay")
        continue
    s = json.loads(summary.read_text())
    rows = sum(1 for _ in open(replayed / chunk.name / "poses.csv")) - 1
    replayed_frames = {n: s["cameras"].get(n, {}).get("captured", 0) for n in on_disk}
    # Each depth frame a row, or dropped by the replay's synchroniser and counted (a few where
    # the camera was opened again within the chunk and its frame counter began again).
    dropped = s["cameras"].get("depth", {}).get("dropped", {})
    replay_drops += sum(dropped.values())
    if rows + sum(dropped.values()) != frames["depth"] or replayed_frames != frames:
        fail(f"{chunk.name}: replayed {rows} rows, {dropped} dropped, frames {replayed_frames} of {frames}")
for name, c in sorted(cameras.items()):
    kept = c.get("recorded", 0) - sum(c.get("lost_after_recording", {}).values())
    if on_disk[name] != kept:
        fail(f"{name}: {on_disk[name]} frames on the disk, the report says {kept} recorded and kept")
print(f"{len(chunks)} chunks ({poses_only} of poses only, the disk full throughout), every session closed "
      f"and replayed: {not any('chunk' in f for f in failures)}; "
      f"frames on the disk: depth {on_disk['depth']}, colour {on_disk['color']}; "
      f"depth frames the replays dropped (counted): {replay_drops}")

# /metrics: a series that only counts up never falls or vanishes.
sample = re.compile(r"^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{[^}]*\})? (\S+)$")
counts_up = ("_total", "_count", "_sum", "_bucket")
last, falls, n = {}, 0, 0
for path in sorted(scrapes.glob("*.txt")):
    series = {}
    for line in path.read_text().splitlines():
        m = sample.match(line)
        if m and m.group(1).endswith(counts_up):
            series[m.group(1) + (m.group(2) or "")] = float(m.group(3))
    if not series:
        continue
    n += 1
    for key, was in last.items():
        if series.get(key, float("-inf")) < was:
            falls += 1
            if falls <= 5:
                fail(f"/metrics {path.stem} s: {key} {was} -> {series.get(key)}")
    last = series
print(f"/metrics: {n} scrapes, {falls} falls of a counter")
if n < 2:
    fail("fewer than two scrapes of /metrics")

latency = report.get("end_to_end_latency", {})
print(
    f"poses {report['poses']} ({report['statuses']}), not written {report['poses_not_written']}; "
    f"latency p99 {latency.get('p99_ms')} ms; {report['cpu_cores']:.2f} cores; chunks {report['chunks']}"
)
print("every loss accounted for" if not failures else f"{len(failures)} checks FAILED")
sys.exit(3 if failures else 0)
