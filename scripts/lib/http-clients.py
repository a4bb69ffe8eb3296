"""Clients polling the daemon's HTTP server as its live page does, for scripts/http-load.

    python3 http-clients.py HOST:PORT CLIENTS SECONDS

Each client, on a thread of its own, asks for /status every second, each picture about three
times a second, /history and /events every two seconds; one more scrapes /metrics every second.
All stop after SECONDS. Prints requests, failures and the slowest answer.
"""
import sys
import threading
import time
import urllib.error
import urllib.request

address, clients, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
lock = threading.Lock()
done = {"requests": 0, "failures": 0, "no_picture": 0, "slowest": 0.0}


def fetch(path):
    start = time.monotonic()
    ok, no_picture = True, False
    try:
        with urllib.request.urlopen(f"http://{address}{path}", timeout=10) as answer:
            answer.read()
            ok = answer.status == 200
    except urllib.error.HTTPError as e:
        # 404 for a picture: the latest pose has no colour frame; an answer all the same.
        no_picture = e.code == 404 and path.startswith("/live/")
        ok = no_picture
    except Exception:  # a refused or failed request is counted, whatever it was
        ok = False
    with lock:
        done["requests"] += 1
        done["failures"] += 0 if ok else 1
        done["no_picture"] += 1 if no_picture else 0
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


page = [("/status", 1.0), ("/live/depth.png", 0.33), ("/live/bottom.png", 0.33), ("/history", 2.0), ("/events", 2.0)]
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
