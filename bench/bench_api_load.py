"""Load test of the service on loopback: req/s, latency percentiles, memory with 8 large jobs queued.

Starts the service (uvicorn on the app factory) on 127.0.0.1 with a throw-away
data folder, then

1. a typical route-planner request (a 2 km delivery route as waypoints -> GeoJSON
   contours at ``--resolution`` m cells, default 20) from ``--clients`` concurrent
   clients, ``--requests`` in all; the baseline is the same map made in-process by the
   library (``gisnoise.maps.pipeline.make_map``) in this run, so the ratio is the
   service's overhead and queueing; the evaluator's own time in that map
   (``evaluate_grid``, timed inside ``make_map``) gives the share of a request's time
   spent outside the evaluator (p50 latency with one client);
2. ``GET /cards`` (a cheap read) the same way;
3. eight large contour jobs queued at once: the server's resident memory (RSS,
   process tree) sampled while they run, against its idle RSS and the peak with
   one such job alone; the jobs are cancelled after ``--job-seconds``.

The share outside the evaluator is given two ways: client-side (``1 - evaluate / latency``,
the latency this bench's HTTP client measures: what a route planner sees, the issue's
number) and server-side (``1 - evaluate / total``, ``total`` the service's own
``Server-Timing`` entry from the request's arrival in the app to its answer's head:
without the client's HTTP stack, the connection and the server's HTTP parser).

``--baseline-tree DIR`` runs the service of another source tree (a worktree of an earlier commit)
and this tree's side by side, one client, request by request alternating, and prints both, their
ratio and whether the answers are byte-identical.

``--during-job`` times single small maps (one client) with the service idle and while one large
contour job runs (interleaved: idle, job, idle, ...), and prints both and their ratio: route
planners' requests should not wait behind a job's work.

``--compare-stacks`` runs uvicorn's plain stack (``--loop asyncio --http h11``) and its fast
one (``uvloop``, ``httptools``; what ``gisnoise serve`` picks when they are installed) side by
side in one run, single-client rounds interleaved, and prints both and their ratio.

Bounded in count and time; talks to 127.0.0.1 only.  Exits non-zero when any
request failed.  Usage: ``python bench/bench_api_load.py [--requests 40] [--clients 4]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import psutil

REPO = Path(__file__).resolve().parent.parent

ROUTE = {"type": "FeatureCollection", "route": {"altitude_reference": "agl"}, "features": [
    {"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": {"alt": a, "speed": 22}}
    for c, a in [([10.5200, 52.2600], 0), ([10.5200, 52.2600], 80), ([10.5350, 52.2660], 80),
                 ([10.5450, 52.2620], 80), ([10.5480, 52.2540], 80), ([10.5480, 52.2540], 0)]]}
CARDS = ["demo-horizontal", "demo-climb", "demo-sink"]


RESOLUTION_M = 20.0


def typical_request() -> dict:
    return {"trajectory": {"format": "waypoints", "data": ROUTE}, "cards": CARDS,
            "grid": {"resolution_m": RESOLUTION_M, "margin_m": 300}, "levels": [45, 50, 55, 60, 65], "metrics": ["LAmax"]}


def large_request(i: int) -> dict:
    req = typical_request()
    req["grid"] = {"resolution_m": 8, "margin_m": 800 + i}  # distinct requests, ~0.2 M cells each
    req["metrics"] = ["LAmax", "LAeq", "SEL"]
    return req


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def stop(procs: Iterable[subprocess.Popen]) -> None:
    """Stop the services started by :func:`start_server`."""
    for proc in procs:
        proc.terminate()
        proc.wait(30)


def load_line() -> str:
    """The machine's load averages (1, 5, 15 min)."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def start_server(data: Path, stack: tuple[str, str] | None = None, tree: Path = REPO) -> tuple[subprocess.Popen, str]:
    """uvicorn on the app factory; ``stack``: its ``(--loop, --http)`` (default: uvicorn's choice, as ``gisnoise
    serve``); ``tree``: the source tree whose ``gisnoise`` it serves (default this one)."""
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("GISNOISE_")}
    env.update(GISNOISE_DATA_DIR=str(data), GISNOISE_TILE_URL="", GISNOISE_WORKERS="1",
               GISNOISE_SEED_CARDS_DIR=str(tree / "gisnoise" / "data" / "cards"))
    if tree != REPO:
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [os.environ.get("PYTHONPATH")])])
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "gisnoise.service.app:create_app", "--factory", "--host",
                             "127.0.0.1", "--port", str(port), "--log-level", "warning",
                             *(("--loop", stack[0], "--http", stack[1]) if stack else ())], env=env, cwd=str(tree))
    url = f"http://127.0.0.1:{port}"
    end = time.monotonic() + 60
    while time.monotonic() < end:
        try:
            if httpx.get(url + "/health", timeout=1).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("the server did not start")


def rss_mb(proc: subprocess.Popen) -> float:
    p = psutil.Process(proc.pid)
    return sum(q.memory_info().rss for q in [p, *p.children(recursive=True)]) / 2**20


def pct(v: list[float], q: float) -> float:
    s = sorted(v)
    return s[min(len(s) - 1, max(0, int(round(q / 100 * (len(s) - 1)))))]


def load(url: str, method: str, path: str, body: dict | None, n: int, clients: int, max_s: float) -> dict:
    lat: list[float] = []
    evals: list[float] = []  # the evaluator's, the map's and the app's time of each request (its Server-Timing)
    maps: list[float] = []
    totals: list[float] = []
    errors: list[str] = []
    lock = threading.Lock()
    t_end = time.monotonic() + max_s
    local = threading.local()

    def one(_: int) -> None:
        if time.monotonic() > t_end:
            return
        if not hasattr(local, "client"):  # one keep-alive connection per client, as a route planner has
            local.client = httpx.Client(timeout=120)
        t0 = time.perf_counter()
        r = local.client.request(method, url + path, json=body)
        dt = time.perf_counter() - t0
        with lock:
            if r.status_code != 200:
                errors.append(f"{r.status_code} {r.text[:200]}")
            else:
                lat.append(dt)
                timing = dict(part.strip().split(";dur=") for part in r.headers.get("server-timing", "").split(",")
                              if ";dur=" in part)
                if "evaluate" in timing:
                    evals.append(float(timing["evaluate"]) / 1000)
                    maps.append(float(timing["map"]) / 1000)
                    totals.append(float(timing["total"]) / 1000)

    t0 = time.perf_counter()
    with ThreadPoolExecutor(clients) as ex:
        list(ex.map(one, range(n)))
    wall = time.perf_counter() - t0
    share = [1 - e / t for e, t in zip(evals, lat, strict=False)] if len(evals) == len(lat) else []
    share_server = [1 - e / t for e, t in zip(evals, totals, strict=False)] if len(evals) == len(lat) else []
    nan = float("nan")
    return {"n": len(lat), "errors": errors, "rps": len(lat) / wall, "p50": pct(lat, 50), "p90": pct(lat, 90),
            "outside": statistics.median(share) if share else nan,
            "outside_server": statistics.median(share_server) if share_server else nan,
            "outside_ms": statistics.median([t - e for e, t in zip(evals, lat, strict=False)]) if share else nan,
            "outside_server_ms": statistics.median([t - e for e, t in zip(evals, totals, strict=False)])
            if share_server else nan,
            "total_p50": statistics.median(totals) if totals else nan,
            "eval_p50": statistics.median(evals) if evals else float("nan"),
            "map_p50": statistics.median(maps) if maps else float("nan"),
            "p95": pct(lat, 95),
            "p99": pct(lat, 99), "max": max(lat) if lat else float("nan"), "mean": statistics.fmean(lat) if lat else 0}


def direct_baseline(repeats: int) -> tuple[float, float]:
    """Seconds per typical map made in-process by the library (no HTTP), and the evaluator's part of them."""
    import gisnoise.maps.pipeline as pipeline
    from gisnoise.model import cards as gcards

    cards = [gcards.load(REPO / "gisnoise" / "data" / "cards" / f"{c.replace('-', '_')}.json") for c in CARDS]
    req = typical_request()
    spent: list[float] = []
    evaluate = pipeline.evaluate_grid

    def timed_evaluate(*a, **k):  # the evaluator's time inside make_map
        t0 = time.perf_counter()
        out = evaluate(*a, **k)
        spent.append(time.perf_counter() - t0)
        return out

    pipeline.evaluate_grid = timed_evaluate
    times = []
    try:
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                pipeline.make_map(ROUTE, cards, d, resolution_m=RESOLUTION_M, margin_m=300, levels=req["levels"],
                                  metrics=["LAmax"])
                times.append(time.perf_counter() - t0)
    finally:
        pipeline.evaluate_grid = evaluate
    return statistics.median(times), statistics.median(spent)

def memory_with_queued_jobs(url: str, proc: subprocess.Popen, n_jobs: int, job_s: float) -> dict:
    idle = rss_mb(proc)
    # one large job alone: its peak
    jid = httpx.post(url + "/jobs/contours", json=large_request(0), timeout=60).json()["id"]
    peak_one = idle
    while httpx.get(f"{url}/jobs/{jid}").json()["status"] in ("queued", "running"):
        peak_one = max(peak_one, rss_mb(proc))
        time.sleep(0.1)
    alone = httpx.get(f"{url}/jobs/{jid}").json()
    # eight at once
    ids = [httpx.post(url + "/jobs/contours", json=large_request(i + 1), timeout=60).json()["id"]
           for i in range(n_jobs)]
    peak_many = rss_mb(proc)
    t_end = time.monotonic() + job_s
    while time.monotonic() < t_end:
        peak_many = max(peak_many, rss_mb(proc))
        states = [httpx.get(f"{url}/jobs/{i}").json()["status"] for i in ids]
        if all(s not in ("queued", "running") for s in states):
            break
        time.sleep(0.1)
    states = [httpx.get(f"{url}/jobs/{i}").json()["status"] for i in ids]
    for i, s in zip(ids, states, strict=True):
        if s in ("queued", "running"):
            httpx.post(f"{url}/jobs/{i}/cancel")
    return {"idle": idle, "peak_one": peak_one, "peak_many": peak_many, "alone_status": alone["status"],
            "alone_s": (alone["finished"] or 0) - (alone["started"] or 0), "states": states}


STACKS = {"asyncio+h11": ("asyncio", "h11"), "uvloop+httptools": ("uvloop", "httptools")}


def compare_stacks(requests: int, max_s: float) -> int:
    """POST /contours from one client to two servers, uvicorn's plain and fast stack, in interleaved rounds."""
    missing = [m for m in ("uvloop", "httptools") if importlib.util.find_spec(m) is None]
    if missing:
        print(f"--compare-stacks needs {' and '.join(missing)} installed")
        return 2
    rounds = max(1, requests // 5)
    out: dict[str, list[dict]] = {name: [] for name in STACKS}
    with tempfile.TemporaryDirectory(prefix="gisnoise-bench-") as tmp:
        servers = {name: start_server(Path(tmp) / name, stack) for name, stack in STACKS.items()}
        try:
            for _, url in servers.values():
                load(url, "POST", "/contours", typical_request(), 5, 1, max_s)  # warm-up
            for i in range(rounds):  # the order alternates, so neither stack always follows the other
                for name, (_, url) in (list(servers.items()) if i % 2 == 0 else list(servers.items())[::-1]):
                    out[name].append(load(url, "POST", "/contours", typical_request(), 5, 1, max_s))
        finally:
            stop(proc for proc, _ in servers.values())
    print(f"load average after: {load_line()}")
    print(f"POST /contours, one client, {rounds} interleaved rounds of 5 per stack (medians over rounds):")
    med: dict[str, dict[str, float]] = {}
    for name, rs in out.items():
        med[name] = {k: statistics.median(r[k] for r in rs) for k in ("p50", "eval_p50", "total_p50", "outside",
                                                                       "outside_ms", "outside_server",
                                                                       "outside_server_ms")}
        m = med[name]
        print(f"  {name}: p50 {m['p50'] * 1000:.1f} ms, evaluator {m['eval_p50'] * 1000:.1f} ms, app total "
              f"{m['total_p50'] * 1000:.1f} ms; outside the evaluator client-side {m['outside_ms'] * 1000:.1f} ms "
              f"({100 * m['outside']:.0f} %), server-side {m['outside_server_ms'] * 1000:.1f} ms "
              f"({100 * m['outside_server']:.0f} %)")
    a, b = med["asyncio+h11"], med["uvloop+httptools"]
    print(f"ratio uvloop+httptools / asyncio+h11: p50 {b['p50'] / a['p50']:.3f}, client-side time outside the "
          f"evaluator {b['outside_ms'] / a['outside_ms']:.3f}, server-side {b['outside_server_ms'] / a['outside_server_ms']:.3f}")
    errors = [e for rs in out.values() for r in rs for e in r["errors"]]
    for e in errors[:5]:
        print("error:", e)
    return 1 if errors else 0


def during_job(requests: int, tree: Path = REPO) -> int:
    """Small maps (one client) with the service idle and while one large job runs, in alternating rounds."""
    lat: dict[str, list[float]] = {"idle": [], "job": []}
    errors: list[str] = []
    rounds = max(2, requests // 10)
    with tempfile.TemporaryDirectory(prefix="gisnoise-bench-") as tmp:
        proc, url = start_server(Path(tmp) / "data", tree=tree)
        client = httpx.Client(timeout=120)
        try:
            for _ in range(5):
                client.post(url + "/contours", json=typical_request())  # warm-up
            for i in range(2 * rounds):
                state = "idle" if i % 2 == 0 else "job"
                jid = None
                if state == "job":
                    big = large_request(i)
                    big["grid"] = {"resolution_m": 2, "margin_m": 800 + i}  # ~4 M cells: seconds of work
                    jid = client.post(url + "/jobs/contours", json=big).json()["id"]
                    while client.get(f"{url}/jobs/{jid}").json()["status"] == "queued":
                        time.sleep(0.01)
                    time.sleep(0.3)  # the job's blocks are in the pool
                for _ in range(10):
                    t0 = time.perf_counter()
                    r = client.post(url + "/contours", json=typical_request())
                    dt = time.perf_counter() - t0
                    if r.status_code != 200:
                        errors.append(f"{r.status_code} {r.text[:200]}")
                    else:
                        lat[state].append(dt)
                if jid is not None:
                    running = client.get(f"{url}/jobs/{jid}").json()["status"] == "running"
                    if not running:
                        errors.append("the large job ended before the small maps did: make it larger")
                    client.post(f"{url}/jobs/{jid}/cancel")
                    while client.get(f"{url}/jobs/{jid}").json()["status"] in ("queued", "running"):
                        time.sleep(0.05)
        finally:
            client.close()
            stop([proc])
    print(f"load average after: {load_line()}")
    print(f"POST /contours (small map, one client), {len(lat['idle'])} with the service idle, {len(lat['job'])} while "
          "one large contour job runs, alternating rounds of 10:")
    for k, v in lat.items():
        if v:
            print(f"  {k}: p50 {pct(v, 50) * 1000:.1f} ms, p95 {pct(v, 95) * 1000:.1f} ms, max {max(v) * 1000:.1f} ms")
    if lat["idle"] and lat["job"]:
        print(f"ratio while a job runs / idle: p50 {pct(lat['job'], 50) / pct(lat['idle'], 50):.2f}, "
              f"p95 {pct(lat['job'], 95) / pct(lat['idle'], 95):.2f}")
    for e in errors[:5]:
        print("error:", e)
    return 1 if errors else 0


def compare_trees(baseline: Path, requests: int) -> int:
    """POST /contours from one client to the service of ``baseline`` (another source tree, e.g. a worktree of an
    earlier commit) and of this tree, request by request in alternating order."""
    names = {"baseline": baseline.resolve(), "this tree": REPO}
    out: dict[str, dict[str, list[float]]] = {n: {"lat": [], "eval": [], "total": []} for n in names}
    bodies: dict[str, set[bytes]] = {n: set() for n in names}
    errors: list[str] = []
    with tempfile.TemporaryDirectory(prefix="gisnoise-bench-") as tmp:
        servers = {n: start_server(Path(tmp) / str(i), tree=t) for i, (n, t) in enumerate(names.items())}
        clients = {n: httpx.Client(timeout=120) for n in names}
        try:
            for n, (_, url) in servers.items():
                for _ in range(5):
                    clients[n].post(url + "/contours", json=typical_request())  # warm-up
            for i in range(requests):
                for n in (list(names) if i % 2 == 0 else list(names)[::-1]):
                    t0 = time.perf_counter()
                    r = clients[n].post(servers[n][1] + "/contours", json=typical_request())
                    dt = time.perf_counter() - t0
                    if r.status_code != 200:
                        errors.append(f"{n}: {r.status_code} {r.text[:200]}")
                        continue
                    timing = dict(part.strip().split(";dur=") for part in r.headers["server-timing"].split(","))
                    out[n]["lat"].append(dt)
                    out[n]["eval"].append(float(timing["evaluate"]) / 1000)
                    out[n]["total"].append(float(timing["total"]) / 1000)
                    bodies[n].add(r.content)
        finally:
            stop(proc for proc, _ in servers.values())
    print(f"load average after: {load_line()}")
    print(f"POST /contours, one client, {requests} requests to each service, alternating:")
    med: dict[str, dict[str, float]] = {}
    for n, d in out.items():
        lat, ev, tot = d["lat"], d["eval"], d["total"]
        if not lat:
            continue
        m = med[n] = {"p50": pct(lat, 50), "p95": pct(lat, 95), "eval": statistics.median(ev),
                      "out_c": statistics.median([a - b for a, b in zip(lat, ev, strict=True)]),
                      "out_s": statistics.median([a - b for a, b in zip(tot, ev, strict=True)]),
                      "sh_c": statistics.median([1 - b / a for a, b in zip(lat, ev, strict=True)]),
                      "sh_s": statistics.median([1 - b / a for a, b in zip(tot, ev, strict=True)])}
        print(f"  {n} ({names[n]}): p50 {m['p50'] * 1000:.1f} ms, p95 {m['p95'] * 1000:.1f} ms, evaluator "
              f"{m['eval'] * 1000:.1f} ms; outside the evaluator client-side {m['out_c'] * 1000:.2f} ms "
              f"({100 * m['sh_c']:.1f} %), server-side {m['out_s'] * 1000:.2f} ms ({100 * m['sh_s']:.1f} %)")
    if len(med) == 2:
        a, b = med["baseline"], med["this tree"]
        print(f"ratio this tree / baseline: time outside the evaluator client-side {b['out_c'] / a['out_c']:.3f}, "
              f"server-side {b['out_s'] / a['out_s']:.3f}; p50 {b['p50'] / a['p50']:.3f}")
        same = len(bodies["baseline"]) == 1 and bodies["baseline"] == bodies["this tree"]
        print(f"answers byte-identical: {same}")
    for e in errors[:5]:
        print("error:", e)
    return 1 if errors else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=40, help="typical contour requests (default 40)")
    ap.add_argument("--clients", type=int, default=4, help="concurrent clients (default 4)")
    ap.add_argument("--resolution", type=float, default=20.0, help="cell size of the typical request, m (default 20)")
    ap.add_argument("--skip-jobs", action="store_true", help="skip the queued large jobs (part 3)")
    ap.add_argument("--compare-stacks", action="store_true",
                    help="only POST /contours, one client: uvicorn's asyncio+h11 against uvloop+httptools, interleaved")
    ap.add_argument("--during-job", action="store_true",
                    help="only POST /contours, one client: idle against while one large contour job runs")
    ap.add_argument("--tree", type=Path, default=REPO,
                    help="with --during-job: the source tree whose service runs (default this one)")
    ap.add_argument("--baseline-tree", type=Path, default=None,
                    help="only POST /contours, one client: the service of another source tree (a worktree of an "
                         "earlier commit) against this tree's, request by request alternating")
    ap.add_argument("--max-seconds", type=float, default=120, help="time bound of each load phase, s")
    ap.add_argument("--jobs", type=int, default=8, help="large jobs queued at once (default 8)")
    ap.add_argument("--job-seconds", type=float, default=60, help="watch the queued jobs this long, s")
    args = ap.parse_args()
    global RESOLUTION_M
    RESOLUTION_M = args.resolution

    print(f"load average before: {load_line()}")
    if args.compare_stacks:
        return compare_stacks(args.requests, args.max_seconds)
    if args.during_job:
        return during_job(args.requests, args.tree.resolve())
    if args.baseline_tree is not None:
        return compare_trees(args.baseline_tree, args.requests)
    direct_baseline(1)  # imports, kernels loaded
    base, t_eval = direct_baseline(5)
    with tempfile.TemporaryDirectory(prefix="gisnoise-bench-") as tmp:
        proc, url = start_server(Path(tmp) / "data")
        try:
            httpx.post(url + "/contours", json=typical_request(), timeout=120)  # warm-up
            single = load(url, "POST", "/contours", typical_request(), max(10, args.requests), 1, args.max_seconds)
            contours = load(url, "POST", "/contours", typical_request(), args.requests, args.clients,
                            args.max_seconds)
            cards = load(url, "GET", "/cards", None, 20 * args.requests, args.clients, args.max_seconds)
            mem = None if args.skip_jobs else memory_with_queued_jobs(url, proc, args.jobs, args.job_seconds)
        finally:
            stop([proc])

    print("gisnoise service load test (loopback, uvicorn, 1 job worker)")
    print(f"baseline: the same map in-process via make_map: {base * 1000:.0f} ms, of which the evaluator "
          f"{t_eval * 1000:.0f} ms ({100 * (1 - t_eval / base):.0f} % outside it)")
    print(f"POST /contours, one client: p50 {single['p50'] * 1000:.1f} ms, p95 {single['p95'] * 1000:.1f} ms; "
          f"share outside the evaluator {100 * (1 - t_eval / single['p50']):.0f} % against the in-process "
          f"evaluator; per request (its Server-Timing: evaluator p50 {single['eval_p50'] * 1000:.1f} ms, map "
          f"{single['map_p50'] * 1000:.1f} ms, app total {single['total_p50'] * 1000:.1f} ms):")
    print(f"  median share outside the evaluator, client-side (what a planner sees): {100 * single['outside']:.0f} % "
          f"({single['outside_ms'] * 1000:.1f} ms); server-side (app total): {100 * single['outside_server']:.0f} % "
          f"({single['outside_server_ms'] * 1000:.1f} ms) (goal < 30 %)")
    for name, r in ((f"POST /contours (2 km route, {RESOLUTION_M:g} m cells, GeoJSON)", contours),
                    ("GET /cards", cards)):
        print(f"{name}: {r['n']} ok, {len(r['errors'])} errors, {r['rps']:.1f} req/s with {args.clients} clients; "
              f"latency p50 {r['p50'] * 1000:.0f} ms, p95 {r['p95'] * 1000:.0f} ms, p99 {r['p99'] * 1000:.0f} ms, "
              f"max {r['max'] * 1000:.0f} ms")
    print(f"ratio p50 latency / in-process baseline: {contours['p50'] / base:.2f} "
          f"(single-request compute; {args.clients} clients share 2 sync slots)")
    print(f"ratio throughput / (1 / baseline): {contours['rps'] * base:.2f}")
    if mem is None:
        errors = single["errors"] + contours["errors"] + cards["errors"]
        for e in errors[:5]:
            print("error:", e)
        return 1 if errors else 0
    print(f"memory: idle {mem['idle']:.0f} MB; one large job alone peak {mem['peak_one']:.0f} MB "
          f"({mem['alone_status']}, {mem['alone_s']:.1f} s); {args.jobs} queued peak {mem['peak_many']:.0f} MB; "
          f"ratio {args.jobs}-queued / one {mem['peak_many'] / mem['peak_one']:.2f}")
    print(f"queued jobs after {args.job_seconds:.0f} s: {', '.join(mem['states'])} (the rest cancelled)")
    errors = single["errors"] + contours["errors"] + cards["errors"]
    for e in errors[:5]:
        print("error:", e)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
