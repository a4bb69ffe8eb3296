"""Runs a soak's faults (soak-schedule.py's episodes) against a running daemon, and says which
pairs of faults met.

    soak-faults.py SCHEDULE DONE --daemon PID --out DIR --stall FILE --status URL
                   --period SECONDS --camera-pid FILE --until SECONDS [--camera-serial S]

Episodes run one after the other, each at its `not_before` (seconds from this start) or later
when the one before ran late. An episode with a `rotation` is centred on the daemon's next chunk
boundary: the status' chunk count, read every quarter second, says when the current chunk
began, and the next is due a period later. Had a chunk begun off that period meanwhile (a full
disk or a moved directory begins one early), the episode is run again at the next boundary,
twice at most.

Actions: disk-fill (a file in OUT written until the disk is full), disk-free, colour-kill and
colour-start (the fake GigE camera whose process id is in the file --camera-pid, which this
keeps up to date), depth-stall and depth-go (the file --stall made and removed), sighup,
dir-move (the run directory in OUT renamed to `moved-N` beside it) and dir-remove (that copy
removed). Each is written to DONE as "SECONDS ACTION"; then the pairs met, and the episodes
not run before --until. Exits 1 when a pair never met.
"""

import argparse
import itertools
import json
import math
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request

KINDS = ["disk-full", "colour-kill", "depth-stall", "camera-gap", "rotation", "sighup", "dir-move"]

p = argparse.ArgumentParser()
p.add_argument("schedule")
p.add_argument("done")
p.add_argument("--daemon", type=int, required=True)
p.add_argument("--out", type=pathlib.Path, required=True)
p.add_argument("--stall", type=pathlib.Path, required=True)
p.add_argument("--status", required=True)
p.add_argument("--period", type=float, required=True)
p.add_argument("--camera-pid", type=pathlib.Path, required=True)
p.add_argument("--camera-serial", default="MP-FAKE-RIG")
p.add_argument("--until", type=float, required=True)
args = p.parse_args()

episodes = [json.loads(line) for line in open(args.schedule) if line.strip()]
start = time.monotonic()
done = open(args.done, "a", buffering=1)


def now():
    return time.monotonic() - start


def log(what):
    done.write(f"{now():.1f} {what}\n")


# When each chunk began, by the status' count: (seconds, count).
begun = []
stop_polling = threading.Event()


def poll_chunks():
    last = None
    while not stop_polling.is_set():
        try:
            with urllib.request.urlopen(args.status, timeout=2) as r:
                count = json.load(r)["chunks"]
            if count != last:
                begun.append((now(), count))
                last = count
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.25)


threading.Thread(target=poll_chunks, daemon=True).start()
filler = None
moved = []


def act(what):
    global filler
    log(what)
    if what == "disk-fill":
        filler = args.out / "filler"
        # The free space at once, then the last blocks until a write fails (ENOSPC).
        fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        free = os.statvfs(args.out)
        try:
            os.posix_fallocate(fd, 0, free.f_bavail * free.f_frsize)
        except OSError:
            pass
        os.lseek(fd, 0, os.SEEK_END)
        try:
            while os.write(fd, b"\7" * (64 << 10)) > 0:
                pass
        except OSError:
            pass
        os.close(fd)
    elif what == "disk-free":
        if filler is not None:
            filler.unlink(missing_ok=True)
            filler = None
    elif what == "colour-kill":
        pid = int(args.camera_pid.read_text())
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    elif what == "colour-start":
        camera = subprocess.Popen(
            ["arv-fake-gv-camera-0.8", "-i", "127.0.0.1", "-s", args.camera_serial],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        args.camera_pid.write_text(str(camera.pid))
    elif what == "depth-stall":
        args.stall.touch()
    elif what == "depth-go":
        args.stall.unlink(missing_ok=True)
    elif what == "sighup":
        os.kill(args.daemon, signal.SIGHUP)
    elif what == "dir-move":
        runs = [d for d in args.out.iterdir() if d.is_dir() and not d.name.startswith("moved-")]
        if runs:
            to = args.out / f"moved-{len(moved)}"
            runs[0].rename(to)
            moved.append(to)
    elif what == "dir-remove":
        # As an operator would: once the daemon writes in the run directory made again (it
        # noticed the move), or after 5 s; removed sooner, its frames count as removed.
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and not any(
            chunk.is_dir() and any(chunk.iterdir())
            for run in args.out.iterdir()
            if run.is_dir() and not run.name.startswith("moved-")
            for chunk in run.iterdir()
        ):
            time.sleep(0.1)
        if moved:
            shutil.rmtree(moved[-1], ignore_errors=True)


def next_boundary(after):
    """The first chunk boundary at or after `after` seconds, a whole number of periods after
    the current chunk began (None before the first chunk)."""
    if not begun:
        return None
    began = begun[-1][0]
    periods = max(1, math.ceil((after - began) / args.period))
    return began + periods * args.period


def on_the_grid(basis, t):
    """Whether the chunk boundary predicted at `t` from a chunk begun at `basis` was due then:
    every chunk begun between began on the period's grid (a full disk or a moved directory
    begins one early, and the period then counts from it). The daemon may begin the chunk
    due at `t` later (a full disk, a stalled camera: nothing to write yet); it was due."""
    for b, _ in begun:
        if basis + 0.5 < b < t - 1.0:
            j = round((b - basis) / args.period)
            if abs(b - (basis + j * args.period)) > 1.0:
                return False
    return True


def wait_until(t):
    while now() < t:
        time.sleep(min(0.05, max(0.0, t - now())))


met = set()
late = 0.0
not_run = []
for e in episodes:
    kinds, actions, lead = e["kinds"], e["actions"], e["lead"]
    span = max(a[0] for a in actions)
    tries = 3 if "rotation" in kinds else 1
    for attempt in range(tries):
        at = max(e["not_before"] + late, now())
        t = at + lead
        basis = None
        if "rotation" in kinds:
            while not begun and now() < args.until:
                time.sleep(0.25)
            basis = begun[-1][0] if begun else None
            t = next_boundary(at + lead) or t
        if t + span > args.until:
            not_run.append(e)
            break
        for offset, what in actions:
            wait_until(t + offset)
            act(what)
        wait_until(t + span)
        rotated = basis is not None and on_the_grid(basis, t)
        late = max(late, t + span - (e["not_before"] + lead + span))
        if "rotation" not in kinds or rotated:
            met.update(tuple(sorted(pair)) for pair in itertools.combinations(kinds, 2))
            break
        log(f"a chunk began off its period before {t:.1f} s: episode {' + '.join(kinds)} again")
        wait_until(now() + 1)
    else:
        met.update(tuple(sorted(pair)) for pair in itertools.combinations([k for k in kinds if k != "rotation"], 2))
    if not_run:
        break
stop_polling.set()
if filler is not None:
    act("disk-free")
args.stall.unlink(missing_ok=True)
missing = [pair for pair in itertools.combinations(sorted(KINDS), 2) if pair not in met]
print(f"pairs of faults met: {21 - len(missing)} of 21" + (f"; never: {missing}" if missing else ""))
if not_run:
    print(f"episodes not run before {args.until:.0f} s: {len(episodes) - episodes.index(not_run[0])}")
sys.exit(1 if missing else 0)
