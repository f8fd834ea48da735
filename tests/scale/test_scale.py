"""Scale-out test without a Docker engine: what docker/compose.yaml runs, as processes.

Three `isoserve serve` replicas, configured as compose configures them (ISOSERVE_* variables:
--shard K/3, the same --shard-peers, one shared hierarchy cache dir), and Debian's nginx
running docker/nginx.conf with only its "@test" lines changed (listen port, upstream
addresses, web root), all on 127.0.0.1. Checks:
- every volume's requests land on the replica that preloaded it (X-Iso-Replica, X-Iso-Load),
  so isoserve's ring is nginx's ring; together the replicas preload each volume once;
- a repeated mesh request is an nginx cache HIT with the same bytes and ETag, and
  If-None-Match gets 304 through nginx;
- after one replica is killed (SIGKILL, by PID) every volume is still served (on demand,
  hierarchy read from the shared cache dir; concurrent first requests share one load) and
  the cached meshes are still HITs;
- with --token-file on the replicas, a mesh cached for an authorised client is refused
  (the replica's 401) to a client without the token.
Prints PASS/FAIL/SKIP lines (and INFO lines with numbers); exit status 1 on failure. Every
process is stopped by its PID at the end, and listed in $ISO_SCALE_PIDS for the caller's
trap."""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results, Skip  # noqa: E402 - found through the path just set
from client import request  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", os.path.join(ROOT, "build/isoserve")))
NGINX = shutil.which("nginx") or "/usr/sbin/nginx"
CONF = os.path.join(ROOT, "docker/nginx.conf")
WEB = os.path.join(ROOT, "build/web")
MRICRON = "/usr/share/mricron/templates"
REPLICAS = 3
RESULTS = Results("scale" + os.environ.get("ISO_SAN_SUFFIX", ""))  # the asan pass says scale-san
report, check = RESULTS.report, RESULTS.check
cache_status = {"HIT": 0, "MISS": 0}


def free_ports(n):
    """n distinct free ports on 127.0.0.1 (held open together, then released)."""
    socks = []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


class Process:
    """A child process whose output goes to a file; stopped by its PID."""

    def __init__(self, name, args, log_path, env=None, pid_file=None):
        self.name = name
        self.log_path = log_path
        self.pid_file = pid_file
        self.log_file = open(log_path, "w")
        self.proc = subprocess.Popen(args, stdout=self.log_file, stderr=subprocess.STDOUT,
                                     env=env, cwd=ROOT)
        if pid_file:
            with open(pid_file, "a") as f:
                f.write(f"{self.proc.pid}\n")

    def _forget_pid(self):
        """Once reaped, the PID may be reused: take it off the list the shell's trap reads."""
        if not self.pid_file or not os.path.exists(self.pid_file):
            return
        with open(self.pid_file) as f:
            pids = [p for p in f.read().split() if p != str(self.proc.pid)]
        with open(self.pid_file, "w") as f:
            f.write("".join(p + "\n" for p in pids))

    def log(self):
        with open(self.log_path) as f:
            return f.read()

    def alive(self):
        return self.proc.poll() is None

    def stop(self, sig=signal.SIGTERM, timeout=30):
        """Signals the PID (if it still runs) and waits; returns the exit status."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, sig)
        try:
            rc = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.kill(self.proc.pid, signal.SIGKILL)
            rc = self.proc.wait(timeout=10)
        self.log_file.close()
        self._forget_pid()
        return rc


def wait_for(fn, timeout, what):
    deadline = time.time() + timeout
    last = None
    while time.time() < deadline:
        try:
            if fn():
                return
        except OSError as e:
            last = e
        time.sleep(0.05)
    raise RuntimeError(f"timed out waiting for {what} ({last})")


# ---------------------------------------------------------------- the deployment

def catalog_entries():
    """Volumes found on every machine: analytic fields, and mricron-data's NIfTI templates
    when installed (scripts/setup.sh installs them). Enough of them that each replica
    usually owns a few."""
    entries = []
    for name, level in (("sphere", 0), ("torus", 0), ("ml", 0.5), ("spike", 0.5), ("ijk", 3000)):
        for n in (24, 32, 40):
            entries.append({"id": f"{name}-{n}", "path": f"field:{name}:{n}", "levels": [level]})
    for name, level in (("ch2bet", 30), ("ch2", 60)):
        if os.path.exists(f"{MRICRON}/{name}.nii.gz"):
            entries.append({"id": name, "path": f"{MRICRON}/{name}.nii.gz", "levels": [level]})
    return entries


def nginx_conf(text, listen, upstreams, web_root):
    """docker/nginx.conf with only the lines marked "@test" changed: the listen port, the
    upstream addresses (isoserve-K:8080 -> 127.0.0.1:PORT_K) and the web root."""
    out = []
    for line in text.splitlines(keepends=True):
        if "# @test" in line:
            line = re.sub(r"listen 8080;", f"listen 127.0.0.1:{listen};", line)
            line = re.sub(r"isoserve-(\d+):8080", lambda m: upstreams[int(m.group(1))], line)
            line = re.sub(r"root \S+;", f"root {web_root};", line)
        out.append(line)
    return "".join(out)


class Deployment:
    def __init__(self, tmp, pid_file, entries=None, extra_env=None):
        """Replicas and nginx with their files under tmp; entries: the catalog (default
        catalog_entries()); extra_env: more ISOSERVE_ variables for every replica."""
        self.tmp = tmp
        self.entries = entries or catalog_entries()
        catalog = os.path.join(tmp, "catalog.json")
        with open(catalog, "w") as f:
            json.dump({"volumes": self.entries}, f)
        ports = free_ports(REPLICAS + 1)
        self.front = ports[0]
        self.replica_ports = ports[1:]
        self.peers = [f"127.0.0.1:{p}" for p in self.replica_ports]
        hierarchies = os.path.join(tmp, "hierarchies")  # compose: one volume for all replicas
        os.mkdir(hierarchies)
        self.replicas = []
        for k, port in enumerate(self.replica_ports):
            env = dict(os.environ, ISOSERVE_LISTEN=f"127.0.0.1:{port}",
                       ISOSERVE_SHARD=f"{k}/{REPLICAS}", ISOSERVE_SHARD_PEERS=",".join(self.peers),
                       ISOSERVE_CATALOG=catalog, ISOSERVE_CACHE_DIR=hierarchies,
                       ISOSERVE_THREADS="2", ISOSERVE_CACHE_MB="64", ISOSERVE_DRAIN_SECONDS="5",
                       **(extra_env or {}))
            self.replicas.append(Process(f"replica{k}", [BIN, "serve"],
                                         os.path.join(tmp, f"replica{k}.log"), env, pid_file))
        for k, r in enumerate(self.replicas):
            port = self.replica_ports[k]
            wait_for(lambda: request(port, "/healthz", timeout=2).status == 200, 60,
                     f"replica {k} ready:\n{r.log()}")
        # nginx as compose's front runs it: its prefix is a writable dir (pid, temp, cache).
        # Its workers drop to nobody when the test runs as root: they must read the prefix.
        prefix = os.path.join(tmp, "nginx")
        os.mkdir(prefix)
        os.chmod(tmp, 0o755)
        os.chmod(prefix, 0o755)
        # The web client from a copy in the prefix: a private checkout (0700, as root) is
        # closed to the workers, as a real image's files never are.
        web = os.path.join(prefix, "web")
        shutil.copytree(WEB, web)
        for d, _, names in os.walk(web):
            os.chmod(d, 0o755)
            for n in names:
                os.chmod(os.path.join(d, n), 0o644)
        with open(CONF) as f:
            self.conf_original = f.read()
        self.conf = nginx_conf(self.conf_original, self.front, self.peers, web)
        conf_path = os.path.join(prefix, "nginx.conf")
        with open(conf_path, "w") as f:
            f.write(self.conf)
        self.nginx = Process("nginx", [NGINX, "-g", "daemon off;", "-p", prefix + "/", "-c", conf_path],
                             os.path.join(tmp, "nginx.log"), None, pid_file)
        wait_for(lambda: request(self.front, "/healthz", timeout=2).status == 200, 20,
                 f"nginx answering:\n{self.nginx.log()}")

    def get(self, target, headers=None, method="GET"):
        r = request(self.front, target, headers, method)
        status = r.getheader("X-Cache-Status")
        if status in cache_status:
            cache_status[status] += 1
        return r

    def stop(self):
        rcs = {}
        for p in [self.nginx] + self.replicas:
            if p is not None:
                rcs[p.name] = p.stop(signal.SIGQUIT if p is self.nginx else signal.SIGTERM)
        return rcs


def mesh_target(entry, tolerance=1):
    level = entry["levels"][0]
    return f"/v1/volumes/{entry['id']}/mesh?level={level}&tolerance={tolerance}&normals=none"


# ---------------------------------------------------------------- the checks

def run(d):
    owner = {}  # volume id -> the replica (peer name) that preloads it

    def substitution_only_marked_lines():
        a, b = d.conf_original.splitlines(), d.conf.splitlines()
        assert len(a) == len(b)
        changed = [(x, y) for x, y in zip(a, b) if x != y]
        assert changed and all("# @test" in x for x, _ in changed), changed
    check("nginx_conf_only_marked_lines_changed", substitution_only_marked_lines)

    def catalog_through_nginx():
        r = d.get("/v1/volumes")
        assert r.status == 200, r.status
        listed = {v["id"]: v for v in json.loads(r.body)["volumes"]}
        assert set(listed) == {e["id"] for e in d.entries}, sorted(listed)
        for vid, v in listed.items():
            assert v["shard"] in d.peers, v
            owner[vid] = v["shard"]
        counts = {p: sum(1 for o in owner.values() if o == p) for p in d.peers}
        print(f"INFO {RESULTS.label}.shards: {len(owner)} volumes over {REPLICAS} replicas: "
              f"{sorted(counts.values(), reverse=True)}", flush=True)
    check("catalog_lists_every_volume_with_its_shard", catalog_through_nginx)

    def preloaded_once():
        loaded = 0
        for k, port in enumerate(d.replica_ports):
            text = request(port, "/metrics").body.decode()
            m = re.search(r"^isoserve_volumes_loaded (\d+)", text, re.M)
            assert m, "no isoserve_volumes_loaded gauge"
            mine = sum(1 for o in owner.values() if o == d.peers[k])
            assert int(m.group(1)) == mine, (k, m.group(1), mine)
            loaded += int(m.group(1))
        assert loaded == len(d.entries), (loaded, len(d.entries))
    check("each_volume_preloaded_by_exactly_one_replica", preloaded_once)

    def routed_to_shard():
        wrong = []
        for e in d.entries:
            r = d.get(f"/v1/volumes/{e['id']}")
            got = (r.status, r.getheader("X-Iso-Replica"), r.getheader("X-Iso-Load"))
            if got != (200, owner[e["id"]], "preloaded"):
                wrong.append((e["id"], owner[e["id"]], got))
        assert not wrong, wrong
    check("nginx_routes_each_volume_to_its_preloading_replica", routed_to_shard)

    bodies = {}  # mesh target -> (etag, bytes)

    def mesh_cached():
        timing = []  # (bytes, ms of the MISS, ms of the HIT)
        for e in d.entries:
            t = mesh_target(e)
            t0 = time.perf_counter()
            first = d.get(t)
            t1 = time.perf_counter()
            assert first.status == 200, (t, first.status, first.body[:200])
            assert first.getheader("X-Cache-Status") == "MISS", (t, first.getheader("X-Cache-Status"))
            assert first.getheader("X-Iso-Replica") == owner[e["id"]], (t, first.getheader("X-Iso-Replica"))
            assert int(first.getheader("X-Iso-Triangles")) > 0, (t, "an empty mesh proves little")
            again = d.get(t)
            timing.append((len(first.body), (t1 - t0) * 1000, (time.perf_counter() - t1) * 1000))
            assert again.getheader("X-Cache-Status") == "HIT", (t, again.getheader("X-Cache-Status"))
            assert again.body == first.body and again.getheader("ETag") == first.getheader("ETag"), t
            bodies[t] = (first.getheader("ETag"), first.body)
        nbytes = sum(len(b) for _, b in bodies.values())
        size, miss, hit = max(timing)
        print(f"INFO {RESULTS.label}.meshes: {len(bodies)} meshes, {nbytes} bytes cached at nginx; the largest "
              f"({size} bytes): {miss:.0f} ms through nginx to its replica, {hit:.1f} ms from nginx's cache",
              flush=True)
    check("repeated_mesh_is_nginx_cache_hit_with_same_bytes", mesh_cached)

    def conditional():
        t, (etag, _) = next(iter(bodies.items()))
        r = d.get(t, {"If-None-Match": etag})
        assert r.status == 304 and r.body == b"", (r.status, r.body[:100])
        assert r.getheader("ETag") == etag
        # Not cached yet: nginx fetches the full mesh for its cache, and still answers 304.
        e = d.entries[0]
        fresh = mesh_target(e, tolerance=2)
        direct = request(int(owner[e["id"]].rsplit(":", 1)[1]), fresh)
        r = d.get(fresh, {"If-None-Match": direct.getheader("ETag")})
        assert r.status == 304 and r.getheader("X-Cache-Status") == "MISS", (r.status, r.getheader("X-Cache-Status"))
        r = d.get(fresh)
        assert r.status == 200 and r.getheader("X-Cache-Status") == "HIT" and r.body == direct.body
    check("if_none_match_304_through_nginx", conditional)

    def web_client():
        if not os.path.exists(os.path.join(WEB, "index.html")):
            raise Skip("build/web is not built (make web)")
        r = d.get("/")
        assert r.status == 200 and b"<!doctype html" in r.body.lower(), (r.status, r.body[:80])
        assert "X-Iso-Replica" not in r.headers, "the web client should come from nginx's files"
    check("nginx_serves_the_web_client", web_client)

    # Kill the replica that owns the most volumes, as a crash would (no drain).
    victim = max(range(REPLICAS), key=lambda k: sum(1 for o in owner.values() if o == d.peers[k]))
    lost = sorted(v for v, o in owner.items() if o == d.peers[victim])

    def kill_one():
        d.replicas[victim].stop(signal.SIGKILL)
        assert not d.replicas[victim].alive()
        print(f"INFO {RESULTS.label}.killed: replica {victim} ({d.peers[victim]}), which preloaded "
              f"{len(lost)} volumes", flush=True)
    check("kill_one_replica_by_pid", kill_one)

    def concurrent_first_requests_load_once():
        """Requests racing for a lost volume (its document: not cached, so nginx passes every
        one on) all wait for one load on the replica nginx fails over to."""
        vid = max(lost, key=lambda v: (v.startswith("ch2"), v.endswith("40")))  # slowest to load
        results = []
        start = threading.Barrier(6)

        def one():
            start.wait(timeout=10)
            r = d.get(f"/v1/volumes/{vid}")
            results.append((r.status, r.getheader("X-Iso-Load")))
        threads = [threading.Thread(target=one) for _ in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
        assert results == [(200, "on-demand")] * 6, results
        loads = sum(len(re.findall(rf"\] {re.escape(vid)}: \d+x", r.log()))
                    for k, r in enumerate(d.replicas) if k != victim)
        assert loads == 1, f"{vid} loaded {loads} times"
    check("concurrent_first_requests_load_once", concurrent_first_requests_load_once)

    def all_reachable():
        wrong = []
        for e in d.entries:
            r = d.get(f"/v1/volumes/{e['id']}")
            replica, load = r.getheader("X-Iso-Replica"), r.getheader("X-Iso-Load")
            if r.status != 200 or replica == d.peers[victim]:
                wrong.append((e["id"], r.status, replica))
            elif e["id"] in lost and (load != "on-demand" or not json.loads(r.body)["hierarchy"]["from_file"]):
                wrong.append((e["id"], "expected on-demand from the shared hierarchy", load))
            elif e["id"] not in lost and (replica != owner[e["id"]] or load != "preloaded"):
                wrong.append((e["id"], "moved although its replica lives", replica, load))
        assert not wrong, wrong
        on_demand = 0
        for k, port in enumerate(d.replica_ports):
            if k != victim:
                text = request(port, "/metrics").body.decode()
                on_demand += int(re.search(r"^isoserve_volumes_loaded_on_demand (\d+)", text, re.M).group(1))
        assert on_demand == len(lost), (on_demand, lost)
    check("every_volume_reachable_after_kill", all_reachable)

    def cache_survives():
        for t, (etag, body) in bodies.items():
            r = d.get(t)
            assert r.status == 200 and r.getheader("X-Cache-Status") == "HIT", (t, r.status, r.getheader("X-Cache-Status"))
            assert r.body == body and r.getheader("ETag") == etag, t
    check("nginx_cache_survives_the_kill", cache_survives)

    def new_mesh_after_kill():
        for vid in lost:
            e = next(x for x in d.entries if x["id"] == vid)
            r = d.get(mesh_target(e, tolerance=3))
            assert r.status == 200 and r.getheader("X-Iso-Replica") != d.peers[victim], (vid, r.status)
            assert int(r.getheader("X-Iso-Triangles")) >= 0
    check("new_meshes_of_lost_volumes_after_kill", new_mesh_after_kill)


TOKEN = "nginx-test-token-0123456789abcdef"


def token_behind_nginx(tmp, pid_file):
    """Replicas with --token-file behind docker/nginx.conf: an authorised client's mesh is
    cached and answered from the cache, and a client without the token, or with a wrong
    one, still gets the replica's 401 for that cached mesh, never its bytes (nginx asks a
    replica about every mesh request: auth_request)."""
    os.mkdir(tmp)
    token_file = os.path.join(tmp, "token")
    with open(token_file, "w") as f:
        f.write(TOKEN + "\n")
    entries = [{"id": "sphere-24", "path": "field:sphere:24", "levels": [4]}]
    d = Deployment(tmp, pid_file, entries, {"ISOSERVE_TOKEN_FILE": token_file})
    try:
        target = "/v1/volumes/sphere-24/mesh?level=4&tolerance=1&normals=none"
        ok = {"Authorization": f"Bearer {TOKEN}"}
        first = d.get(target, ok)
        assert first.status == 200 and first.getheader("X-Cache-Status") == "MISS", (first.status, first.body[:200])
        again = d.get(target, ok)
        assert again.status == 200 and again.getheader("X-Cache-Status") == "HIT" and again.body == first.body
        etag = first.getheader("ETag")

        def refused(headers, detail):
            r = d.get(target, headers)
            assert r.status == 401 and r.body != first.body, (headers, r.status)
            assert r.getheader("Content-Type") == "application/problem+json", r.getheader("Content-Type")
            assert r.getheader("WWW-Authenticate") == 'Bearer realm="isoserve"', r.getheader("WWW-Authenticate")
            assert json.loads(r.body) == {"type": "urn:isoserve:problem:unauthorized", "title": "Unauthorized",
                                          "status": 401, "detail": detail,
                                          "instance": "/v1/volumes/sphere-24/mesh"}, r.body
        need = 'this server needs "Authorization: Bearer TOKEN"'
        refused({}, need)
        refused({"If-None-Match": etag}, need)  # not a 304 from the cache either
        refused({"Authorization": "Bearer " + "x" * len(TOKEN)}, "the bearer token is not this server's")
        r = d.get(target, dict(ok, **{"If-None-Match": etag}))
        assert r.status == 304, r.status
        r = d.get(target, ok)
        assert r.status == 200 and r.getheader("X-Cache-Status") == "HIT" and r.body == first.body
        assert d.get("/v1/volumes").status == 401 and d.get("/v1/volumes", ok).status == 200
        assert TOKEN not in open(os.path.join(tmp, "nginx.log")).read(), "the token reached nginx's log"
    finally:
        rcs = d.stop()
    assert all(rc == 0 for rc in rcs.values()), rcs


def bad_options(tmp):
    env = {k: v for k, v in os.environ.items() if not k.startswith("ISOSERVE_")}
    cases = ((["--shard", "3/3", "--shard-peers", "a:1,b:2,c:3"], {}, "0 <= K < N"),
             (["--shard", "0/3"], {}, "go together"),
             (["--shard", "0/2", "--shard-peers", "a:1,b:2,c:3"], {}, "names 3 replicas"),
             (["--shard", "0/2", "--shard-peers", "a:1,a:1"], {}, "named twice"),
             (["--shard", "0/2", "--shard-peers", "a:1,"], {}, "empty peer"),
             ([], {"ISOSERVE_THREADS": "zero"}, "ISOSERVE_THREADS"))
    for args, extra, words in cases:
        p = subprocess.run([BIN, "serve", "--listen", "127.0.0.1:0", *args], capture_output=True,
                           text=True, timeout=30, env=dict(env, **extra))
        assert p.returncode == 1 and words in p.stderr, (args, extra, p.returncode, p.stderr)


def flag_beats_environment(tmp, pid_file):
    """An ISOSERVE_ variable is the default; the flag given on the command line wins."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ISOSERVE_")}
    env.update(ISOSERVE_LISTEN="127.0.0.1:1", ISOSERVE_CATALOG="/nonexistent.json",
               ISOSERVE_REPLICA_NAME="from-env")
    catalog = os.path.join(tmp, "one.json")
    with open(catalog, "w") as f:
        json.dump({"volumes": [{"id": "s", "path": "field:sphere:16"}]}, f)
    p = Process("flags", [BIN, "serve", "--listen", "127.0.0.1:0", "--catalog", catalog],
                os.path.join(tmp, "flags.log"), env, pid_file)
    try:
        wait_for(lambda: re.search(r"listening on http://127\.0\.0\.1:(\d+)/", p.log()), 20, "listening")
        port = int(re.search(r"listening on http://127\.0\.0\.1:(\d+)/", p.log()).group(1))
        wait_for(lambda: request(port, "/healthz", timeout=2).status == 200, 20, "ready")
        r = request(port, "/v1/volumes/s")
        assert r.status == 200 and r.getheader("X-Iso-Replica") == "from-env", (r.status, r.headers)
    finally:
        assert p.stop() == 0


def main():
    if not os.access(BIN, os.X_OK):
        print(f"FAIL {RESULTS.label}.binary: {BIN} missing (run make)")
        return 1
    if not os.access(NGINX, os.X_OK):
        print(f"SKIP {RESULTS.label}.nginx: Debian's nginx is not installed (scripts/setup.sh installs it)")
        return 0
    tmp = tempfile.mkdtemp(prefix="isoserve-scale-")
    pid_file = os.environ.get("ISO_SCALE_PIDS", os.path.join(tmp, "pids"))
    start = time.time()
    d = None
    try:
        d = Deployment(tmp, pid_file)
        run(d)
    except Exception as e:  # noqa: BLE001 - a deployment that does not start is one failure
        report("deployment_starts", False, f"{type(e).__name__}: {e}")
    finally:
        if d is not None:
            rcs = d.stop()
            survivors = {n: rc for n, rc in rcs.items() if n.startswith("replica") and rc != -signal.SIGKILL}
            report("replicas_and_nginx_stop_cleanly",
                   all(rc == 0 for rc in survivors.values()) and rcs["nginx"] == 0, str(rcs))
            total = cache_status["HIT"] + cache_status["MISS"]
            if total:
                print(f"INFO {RESULTS.label}.nginx_cache: {cache_status['HIT']} HIT, {cache_status['MISS']} MISS "
                      f"({100.0 * cache_status['HIT'] / total:.0f}% of mesh requests)", flush=True)
    check("token_not_bypassed_by_nginx_cache", lambda: token_behind_nginx(os.path.join(tmp, "token"), pid_file))
    check("shard_option_errors", lambda: bad_options(tmp))
    check("flag_beats_environment", lambda: flag_beats_environment(tmp, pid_file))
    print(f"INFO {RESULTS.label}.seconds: {time.time() - start:.1f}", flush=True)
    if RESULTS.failures:
        for name in ("replica0.log", "replica1.log", "replica2.log", "nginx.log"):
            path = os.path.join(tmp, name)
            if os.path.exists(path):
                print(f"--- {name} (last lines)")
                print("".join(open(path).readlines()[-15:]), flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
