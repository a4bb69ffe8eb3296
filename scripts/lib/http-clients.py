"""Clients polling the daemon's HTTP server as its live page does, for scripts/http-load.

    python3 http-clients.py HOST:PORT CLIENTS SECONDS

Each client, on a thread of its own, asks for /status and each of the three pictures every
second, /history every five seconds and /events every two; one more scrapes /metrics every
second.
They start once the daemon answers and stop SECONDS later. Prints requests, failures and the slowest answer.
"""
import sys
import threading
import time
import urllib.error
import urllib.request

address, clients, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
lock = threading.Lock()
done = {"requests": 0, "failures": 0, "no_picture": 0, "slowest": 0.0}
why = {}


def fetch(path):
    start = time.monotonic()
    ok, no_picture, reason = True, False, ""
    try:
        with urllib.request.urlopen(f"http://{address}{path}", timeout=10) as answer:
            answer.read()
            ok = answer.status == 200
    except urllib.error.HTTPError as e:
        # 404 for a picture: the latest pose has no colour frame; an answer all the same.
        no_picture = e.code == 404 and path.startswith("/live/")
        ok = no_picture
        reason = f"{path} answered {e.code}"
    except Exception as e:  # a refused or failed request is counted, whatever it was
        ok = False
        reason = f"{path}: {type(e).__name__} {e}"
    with lock:
        done["requests"] += 1
        done["failures"] += 0 if ok else 1
        done["no_picture"] += 1 if no_picture else 0
        if not ok:
            why[reason] = why.get(reason, 0) + 1
        done["slowest"] = max(done["slowest"], time.monotonic() - start)


def client(schedule):
    end = time.monotonic() + seconds
    due = {path: time.monotonic() for path, _ in schedule}
    while time.monotonic() < end:
        now = time.monotonic()
        for path, every in schedule:
            if now >= due[path]:
                fetch(path)
                due[path] = now + every
        time.sleep(0.02)


# The daemon starts with the clients: wait (at most 30 s) until it serves.
deadline = time.monotonic() + 30
while True:
    try:
        urllib.request.urlopen(f"http://{address}/status", timeout=2).read()
        break
    except Exception:  # not listening yet
        if time.monotonic() > deadline:
            sys.exit(f"the daemon at {address} did not answer within 30 s")
        time.sleep(0.1)

page = [("/status", 1.0), ("/live/depth.png", 1.0), ("/live/mouse.png", 1.0), ("/live/bottom.png", 1.0),
        ("/history", 5.0), ("/events", 2.0)]
threads = [threading.Thread(target=client, args=(page,)) for _ in range(clients)]
threads.append(threading.Thread(target=client, args=([("/metrics", 1.0)],)))
for t in threads:
    t.start()
for t in threads:
    t.join()
print(
    f" clients: {done['requests']} requests, {done['failures']} failed, {done['no_picture']} pictures not there yet, "
    f"slowest {done['slowest'] * 1000:.0f} ms"
)
for reason, n in sorted(why.items(), key=lambda kv: -kv[1])[:5]:
    print(f"   failed: {n} x {reason}")
