"""Hostile HTTP clients and faults against real `isoserve serve` daemons on 127.0.0.1.

Raw sockets where http.client would tidy the request: over-long URIs and headers, thousands
of query parameters, percent-encoding tricks (%00, %2F, %2e%2e) in ids, NaN/inf/huge
numbers, other methods, HTTP/1.0, pipelining, a connection limit and slow clients
(slowloris must not starve a normal request; --connection-timeout 2 closes them), the
bearer token (--token-file), CORS origins, --max-triangles, and the hierarchy cache's
faults: a write that fails (file size limit, like a full disk), a kill -9 during a build,
a truncated file. Every answer is checked by exact status and exact problem body.
Servers use $ISOSERVE_BIN (tests/run.sh runs this with the normal and the sanitizer build).
Prints PASS/FAIL/SKIP lines; exit status 1 on failure."""

import json
import os
import re
import resource
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
import test_http  # noqa: E402 - the Server class and BIN, found through the path just set
from results import Results, Skip  # noqa: E402

BIN = test_http.BIN
LABEL = "http-hostile" + os.environ.get("ISO_SAN_SUFFIX", "")
RESULTS = Results(LABEL)
TOKEN = "s3cret-token-0123456789abcdef"


def raw(port, data, timeout=10):
    """Sends bytes on a fresh connection and reads until the server closes it."""
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    try:
        s.sendall(data)
        out = b""
        while True:
            try:
                chunk = s.recv(65536)
            except ConnectionResetError:
                break
            if not chunk:
                break
            out += chunk
        return out
    finally:
        s.close()


def responses(data):
    """Splits raw bytes into (status, headers dict, body) triples by Content-Length."""
    out = []
    while data:
        head, _, rest = data.partition(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        status = int(lines[0].split()[1])
        headers = {k.lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
        n = int(headers.get("content-length", "0"))
        out.append((status, headers, rest[:n]))
        data = rest[n:]
    return out


class NoAnswer(AssertionError):
    """The server closed the connection without answering (e.g. at its connection limit)."""


def get(port, target, extra=b"", method=b"GET", version=b"HTTP/1.1"):
    req = method + b" " + target + b" " + version + b"\r\nHost: t\r\n" + extra + b"Connection: close\r\n\r\n"
    got = responses(raw(port, req))
    if not got:
        raise NoAnswer(f"{target[:80]!r}: the connection was closed without an answer")
    return got[0]


def expect_problem(port, target, status, body, extra=b"", method=b"GET"):
    """The exact status and the exact problem+json object."""
    st, headers, got = get(port, target, extra, method)
    assert st == status, (target[:80], st, got[:300])
    assert headers.get("content-type") == "application/problem+json", headers.get("content-type")
    assert json.loads(got) == body, (target[:80], got[:400])
    return headers


def problem(status, title, ptype, detail, instance=None, parameter=None):
    p = {"type": f"urn:isoserve:problem:{ptype}", "title": title, "status": status, "detail": detail}
    if parameter:
        p["parameter"] = parameter
    if instance:
        p["instance"] = instance
    return p


def bad_param(param, detail, instance="/v1/volumes/sphere/mesh"):
    return problem(400, "Bad Request", "bad-parameter", detail, instance, param)


NOT_FOUND_ID = "no volume \"(not a valid id)\"; /v1/volumes lists them"
NO_RESOURCE = ("no such resource; the API is /v1/volumes, /v1/volumes/{id}, /v1/volumes/{id}/mesh, "
               "/v1/volumes/{id}/chain, /v1/volumes/{id}/segments, /v1/volumes/{id}/segments/mesh, "
               "/v1/volumes/{id}/segments/{n}/mesh and /v1/status")


# ---------------------------------------------------------------- one open server

def uri_and_headers(port):
    # Past our 4096-byte target limit but inside libmicrohttpd's 64 KiB buffer: our 414.
    expect_problem(port, b"/v1/volumes/" + b"a" * 5000, 414, problem(
        414, "URI Too Long", "uri-too-long", "the request target is 5012 bytes; at most 4096 are accepted"))
    # Past the connection's memory (MHD_OPTION_CONNECTION_MEMORY_LIMIT, 64 KiB): the
    # library answers itself, before any handler, with its own HTML body.
    st, headers, body = get(port, b"/v1/volumes/" + b"a" * 70000)
    assert st == 414 and b"too big" in body, (st, body[:200])
    st, _, body = get(port, b"/healthz", b"X-Big: " + b"b" * 70000 + b"\r\n")
    assert st == 431 and b"too big" in body, (st, body[:200])
    many = b"".join(b"X-H%d: v\r\n" % i for i in range(5000))
    st, _, _ = get(port, b"/healthz", many)
    assert st == 431, st


def query_params(port):
    hundreds = b"&".join(b"a%d=1" % i for i in range(500))  # 3.4 KB, inside the 4096-byte limit
    expect_problem(port, b"/v1/volumes/sphere/mesh?level=4&" + hundreds, 400, problem(
        400, "Bad Request", "bad-parameter", "more than 32 query parameters", "/v1/volumes/sphere/mesh"))
    # 3000 parameters in 20 KB: libmicrohttpd runs out of the connection's 64 KiB while
    # splitting them, logs a 431 and closes the connection without an answer; the server
    # goes on.
    many = b"&".join(b"l=%d" % i for i in range(3000))
    got = raw(port, b"GET /v1/volumes/sphere/mesh?" + many + b" HTTP/1.1\r\nHost: t\r\n\r\n")
    assert got == b"", got[:200]
    assert get(port, b"/healthz")[0] == 200


def numbers(port):
    m = b"/v1/volumes/sphere/mesh?"
    for value, detail in ((b"nan", 'level must be a finite number, not "nan"'),
                          (b"NaN", 'level must be a finite number, not "NaN"'),
                          (b"-inf", 'level must be a finite number, not "-inf"'),
                          (b"1e400", 'level must be a finite number, not "1e400"'),
                          (b"0x10", 'level is not a number: "0x10"'),
                          (b"%201", 'level is not a number: " 1"'),
                          (b"1%00", 'level is not a number: "1%00"'),
                          (b"1e301", "level must be within +-1e+300")):
        expect_problem(port, m + b"level=" + value, 400, bad_param("level", detail))
    expect_problem(port, m + b"level=4&tolerance=inf", 400,
                   bad_param("tolerance", 'tolerance must be a finite number, not "inf"'))
    expect_problem(port, m + b"level=4&tolerance=1e31", 400,
                   bad_param("tolerance", "tolerance must be from 0 to 1e+30, not 1e31"))
    expect_problem(port, m + b"level=4&budget=99999999999999999999", 400,
                   bad_param("budget", 'budget must be a whole number from 1 to 100000000, not "99999999999999999999"'))
    expect_problem(port, m + b"level=4&level=5", 400, bad_param("level", "level is given more than once"))


def encoded_ids(port):
    # A dot-dot, plain or encoded, is no id: ids never start with a dot.
    for target, instance in ((b"/v1/volumes/%2e%2e", "/v1/volumes/.."),
                             (b"/v1/volumes/..", "/v1/volumes/.."),
                             (b"/v1/volumes/.hidden/mesh?level=1", "/v1/volumes/.hidden/mesh")):
        expect_problem(port, target, 404, problem(404, "Not Found", "not-found", NOT_FOUND_ID, instance))
    # An encoded slash stays inside its segment: "sphere%2Fmesh" is one (invalid) id, not
    # the mesh of sphere.
    expect_problem(port, b"/v1/volumes/sphere%2Fmesh?level=4", 404, problem(
        404, "Not Found", "not-found", NOT_FOUND_ID, "/v1/volumes/sphere%2Fmesh"))
    # An encoded NUL does not cut the path short.
    expect_problem(port, b"/v1/volumes/sphere%00", 404, problem(
        404, "Not Found", "not-found", NOT_FOUND_ID, "/v1/volumes/sphere%00"))
    expect_problem(port, b"/v1/volumes/sphere/%2e%2e/%2e%2e/etc/passwd", 404, problem(
        404, "Not Found", "not-found", NO_RESOURCE, "/v1/volumes/sphere/../../etc/passwd"))
    # The web client's files: no dot segment reaches outside its root.
    for target in (b"/%2e%2e/%2e%2e/etc/passwd", b"/../catalog.json", b"/.%2e/x"):
        st, _, body = get(port, target)
        assert st == 404 and b"root:" not in body, (target, st)
    # A plain id with an escaped letter is still that id.
    st, _, body = get(port, b"/v1/volumes/sph%65re")
    assert st == 200 and json.loads(body)["id"] == "sphere", st


def methods_and_versions(port):
    for method in (b"POST", b"PUT", b"DELETE", b"PATCH", b"TRACE", b"BREW"):
        headers = expect_problem(port, b"/v1/volumes", 405, problem(
            405, "Method Not Allowed", "method-not-allowed",
            f"{method.decode()} is not allowed here; use GET", "/v1/volumes"), method=method)
        assert headers.get("allow") == "GET, HEAD, OPTIONS", headers
    st, headers, body = get(port, b"/healthz", version=b"HTTP/1.0")
    assert st == 200 and json.loads(body)["status"] == "ready" and headers.get("connection") == "close", (st, headers)
    st, _, _ = get(port, b"/healthz", version=b"HTTP/9.9")
    assert st == 505, st


def pipelining(port):
    two = (b"GET /healthz HTTP/1.1\r\nHost: t\r\n\r\n"
           b"GET /v1/volumes/%2e%2e HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n")
    got = responses(raw(port, two))
    assert [r[0] for r in got] == [200, 404], [r[0] for r in got]
    assert json.loads(got[1][2])["instance"] == "/v1/volumes/..", got[1][2]


def max_triangles(port):
    expect_problem(port, b"/v1/volumes/ml/mesh?level=0.5&normals=none", 422, problem(
        422, "Unprocessable Content", "mesh-too-large",
        "the mesh has 57074 triangles, more than this server's limit of 20000; a larger "
        "tolerance gives fewer", "/v1/volumes/ml/mesh"))
    # The refusal is not cached, and a mesh within the limit is served meanwhile.
    st, headers, _ = get(port, b"/v1/volumes/sphere/mesh?level=4")
    assert st == 200 and int(headers["x-iso-triangles"]) == 2060, (st, headers.get("x-iso-triangles"))
    st, _, _ = get(port, b"/v1/volumes/ml/mesh?level=0.5&normals=none")
    assert st == 422, st


def held_connections(port, count, deadline_s=1.5):
    """count connections the server keeps open. A connection it closes at once (it had no
    slot free yet) is opened again, all within deadline_s: less than --connection-timeout,
    after which the server closes idle connections on its own."""
    deadline = time.time() + deadline_s
    held = []
    while True:
        held += [socket.create_connection(("127.0.0.1", port), timeout=10) for _ in range(count - len(held))]
        time.sleep(0.2)
        closed, _, _ = select.select(held, [], [], 0)
        for s in closed:  # readable while idle: the server closed it (or reset it)
            held.remove(s)
            s.close()
        if not closed:
            return held
        assert time.time() < deadline, f"{count - len(held)} of {count} connections refused with slots free"


def slow_clients(port, timeout_s, max_conn):
    """Half-sent requests hold connections; a normal request still answers at once; the
    server closes the slow ones after --connection-timeout; past --max-connections new
    connections are refused until slots free up."""
    slow = []
    for _ in range(max_conn // 2):
        s = socket.create_connection(("127.0.0.1", port), timeout=10)
        s.sendall(b"GET /healthz HTTP/1.1\r\nHost: t\r\nX-Slow: ")
        slow.append(s)
    t0 = time.time()
    st, _, _ = get(port, b"/healthz")
    assert st == 200 and time.time() - t0 < 1.5, (st, time.time() - t0)
    # Each slow connection is closed by the server within the timeout (plus slack).
    for s in slow:
        s.settimeout(timeout_s + 3)
        try:
            assert s.recv(1024) == b"", "a slow client got an answer"
        except ConnectionResetError:
            pass
        s.close()
    assert time.time() - t0 < timeout_s + 4, time.time() - t0
    # Fill every slot with idle connections: one more is refused (closed at once). A slot
    # of a closed connection is free only once its thread has finished, which under load
    # takes a moment, so the idle connections are checked to be held, and any the server
    # closed for want of a slot are opened again.
    idle = held_connections(port, max_conn)
    extra = socket.create_connection(("127.0.0.1", port), timeout=5)
    try:
        extra.sendall(b"GET /healthz HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n")
        got = extra.recv(1024)
    except (ConnectionResetError, BrokenPipeError):
        got = b""
    extra.close()
    assert got == b"", got[:80]
    for s in idle:
        s.close()
    # The server frees a slot when the thread of a closed connection has finished, which
    # under load takes a moment: until then a new connection is still refused.
    deadline = time.time() + 5
    while time.time() < deadline:
        try:
            if get(port, b"/healthz")[0] == 200:
                return
        except (OSError, NoAnswer):
            pass
        time.sleep(0.1)
    raise AssertionError("no answer after the idle connections closed")


def cors(port):
    st, headers, _ = get(port, b"/v1/volumes", b"Origin: https://viewer.example\r\n")
    assert st == 200 and headers.get("access-control-allow-origin") == "https://viewer.example", headers
    assert headers.get("vary") == "Origin", headers
    st, headers, _ = get(port, b"/v1/volumes", b"Origin: https://evil.example\r\n")
    assert st == 200 and "access-control-allow-origin" not in headers, headers
    st, headers, _ = get(port, b"/v1/volumes", method=b"OPTIONS")
    assert st == 204 and headers["access-control-allow-headers"] == "If-None-Match, Authorization", headers


def open_server_tests(tmp, catalog):
    s = test_http.Server(["--catalog", catalog, "--web-root", tmp, "--connection-timeout", "2",
                          "--max-connections", "24", "--max-triangles", "20000",
                          "--cors-origin", "https://viewer.example"])
    try:
        for name, fn in (("uri_and_headers", uri_and_headers), ("query_params", query_params),
                         ("numbers", numbers), ("encoded_ids", encoded_ids),
                         ("methods_and_versions", methods_and_versions), ("pipelining", pipelining),
                         ("max_triangles", max_triangles), ("cors_origins", cors),
                         ("slow_clients", lambda p: slow_clients(p, 2, 24))):
            RESULTS.check(name, lambda fn=fn: fn(s.port))
    finally:
        rc = s.stop()
    RESULTS.report("open_server_exit", rc == 0, f"exit status {rc}: {s.log()[-600:]}")
    RESULTS.report("loopback_default", "listening on http://127.0.0.1:" in s.log() and
                   "not loopback" not in s.log(), s.log()[:300])


# ---------------------------------------------------------------- the bearer token

def token_tests(tmp, catalog):
    token_file = os.path.join(tmp, "token")
    with open(token_file, "w") as f:
        f.write(TOKEN + "\n")
    s = test_http.Server(["--catalog", catalog, "--web-root", tmp, "--token-file", token_file])
    try:
        def check():
            port = s.port
            need = problem(401, "Unauthorized", "unauthorized",
                           'this server needs "Authorization: Bearer TOKEN"', "/v1/volumes")
            h = expect_problem(port, b"/v1/volumes", 401, need)
            assert h.get("www-authenticate") == 'Bearer realm="isoserve"', h
            wrong = problem(401, "Unauthorized", "unauthorized", "the bearer token is not this server's", "/v1/volumes")
            for value in (TOKEN[:-1], TOKEN + "x", "x" * len(TOKEN), ""):
                h = expect_problem(port, b"/v1/volumes", 401, wrong, b"Authorization: Bearer " + value.encode() + b"\r\n")
                assert h.get("www-authenticate") == 'Bearer realm="isoserve"', h
            expect_problem(port, b"/v1/volumes", 401, wrong, b"Authorization: Basic " + TOKEN.encode() + b"\r\n")
            expect_problem(port, b"/metrics", 401, dict(need, instance="/metrics"))
            expect_problem(port, b"/v1/volumes/sphere/mesh?level=4", 401, dict(need, instance="/v1/volumes/sphere/mesh"))
            ok = b"Authorization: Bearer " + TOKEN.encode() + b"\r\n"
            assert get(port, b"/v1/volumes", ok)[0] == 200
            assert get(port, b"/v1/volumes", b"Authorization: bearer  " + TOKEN.encode() + b"\r\n")[0] == 200
            assert get(port, b"/v1/volumes/sphere/mesh?level=4", ok)[0] == 200
            assert get(port, b"/metrics", ok)[0] == 200
            # Open: the health probe, the preflight (browsers send it without credentials)
            # and the web client's own files.
            assert get(port, b"/healthz")[0] == 200
            assert get(port, b"/v1/volumes", method=b"OPTIONS")[0] == 204
            assert get(port, b"/")[0] == 200
            assert TOKEN not in s.log() and TOKEN[:12] not in s.log(), "the token reached the log"
        RESULTS.check("bearer_token", check)
    finally:
        s.stop()

    def refusals():
        for content, words in (("", "at least 16"), ("short\n", "at least 16"),
                               ("has a blank inside it!\n", "blank or a control byte")):
            with open(token_file, "w") as f:
                f.write(content)
            p = subprocess.run([BIN, "serve", "--catalog", catalog, "--listen", "127.0.0.1:0",
                                "--token-file", token_file], capture_output=True, text=True, timeout=30)
            assert p.returncode == 1 and words in p.stderr and f"--token-file {token_file}" in p.stderr, p.stderr
            assert content.strip() == "" or content.strip() not in p.stderr, "the token was printed"
        p = subprocess.run([BIN, "serve", "--catalog", catalog, "--token-file", "/nonexistent/token"],
                           capture_output=True, text=True, timeout=30)
        assert p.returncode == 1 and "--token-file /nonexistent/token: No such file or directory" in p.stderr, p.stderr
    RESULTS.check("token_file_refusals", refusals)


# ---------------------------------------------------------------- one request out of memory

def vm_bytes(pid, key="VmSize"):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    raise AssertionError(f"no {key} in /proc/{pid}/status")


ARENA_HEAP = 64 << 20    # glibc reserves a thread arena's heap in aligned blocks of this size
THREAD_STACK = 8 << 20   # and a thread's stack (the default ulimit -s), below a guard page


def mapped_bytes(pid):
    """The process's mappings in bytes: malloc arenas' heaps, thread stacks, and the rest."""
    maps = []
    with open(f"/proc/{pid}/maps") as f:
        for line in f:
            fields = line.split()
            start, end = (int(x, 16) for x in fields[0].split("-"))
            anonymous = fields[4] == "0" and len(fields) == 5
            maps.append((start, end, fields[1], anonymous))
    sizes = {"arenas": 0, "stacks": 0, "other": 0}
    i = 0
    while i < len(maps):
        start, end, perms, anonymous = maps[i]
        # An arena heap: anonymous pieces (used and reserved) from a 64 MiB boundary on,
        # adding up to exactly 64 MiB.
        j = i
        while anonymous and j + 1 < len(maps) and maps[j + 1][3] and maps[j + 1][0] == maps[j][1] \
                and maps[j][1] - start < ARENA_HEAP:
            j += 1
        if anonymous and start % ARENA_HEAP == 0 and maps[j][1] - start == ARENA_HEAP:
            sizes["arenas"] += ARENA_HEAP
            i = j + 1
            continue
        if anonymous and perms.startswith("---") and end - start == 4096 and i + 1 < len(maps) \
                and maps[i + 1][0] == end and maps[i + 1][1] - end == THREAD_STACK and maps[i + 1][2].startswith("rw"):
            sizes["stacks"] += 4096 + THREAD_STACK
            i += 2
            continue
        sizes["other"] += end - start
        i += 1
    return sizes


def write_noise_nrrd(path, n, seed):
    """n^3 uint8 white noise: at level 127.5 nearly every cell crosses, so the exact mesh has
    about 3 triangles per voxel (12.9 million at n = 160) from a 4 MB volume."""
    import numpy as np  # Debian's python3-numpy, as test_http.py uses
    data = np.random.default_rng(seed).integers(0, 256, size=(n, n, n), dtype=np.uint8)
    with open(path, "wb") as f:
        f.write(f"NRRD0004\ntype: uint8\ndimension: 3\nsizes: {n} {n} {n}\nencoding: raw\n\n".encode())
        f.write(data.tobytes())


def out_of_memory(tmp):
    """One request whose mesh cannot be allocated fails alone: the daemon's address space is
    capped (RLIMIT_AS, set on the running process once its volumes are loaded) a little
    above what it uses, so the 12.9-million-triangle exact mesh of a noise volume cannot be
    allocated; that request gets 503 with a problem body naming the volume and the step
    that ran out, and the next request and /healthz are answered as usual. Twice: with 48
    MiB to spare the extraction itself fails; with 700 MiB it succeeds (about 340 MiB) and
    the Draco encoder or the edge census beside it fails. Under ASan the cap cannot work: its
    shadow memory reserves terabytes of address space up front."""
    noise = os.path.join(tmp, "noise.nrrd")
    write_noise_nrrd(noise, 160, 7)
    cat = os.path.join(tmp, "oom.json")
    json.dump({"volumes": [{"id": "noise", "path": noise, "levels": [127.5]},
                           {"id": "sphere", "path": "field:sphere:24", "levels": [4]}]}, open(cat, "w"))
    # One worker: the thread that will run the huge request has its malloc arena before
    # the cap is measured. No background chains: building the noise surface's (12.9 million
    # triangles) would take the memory this test measures, at a time the test cannot know.
    s = test_http.Server(["--catalog", cat, "--threads", "1", "--chain-background", "off"])
    try:
        pid = s.proc.pid
        reserved = vm_bytes(pid)
        if reserved > 1 << 40:
            raise Skip(f"the daemon reserves {reserved >> 40} TiB of address space (ASan's shadow "
                       "memory), so RLIMIT_AS cannot cap one request's allocations")
        small = "/v1/volumes/sphere/mesh?level=4&tolerance=0.5"
        st, headers, _ = get(s.port, small.encode())
        assert st == 200, st
        triangles = headers["x-iso-triangles"]
        for _ in range(3):  # connection threads' stacks and arenas exist before the cap
            st, headers, _ = get(s.port, small.encode())
            assert st == 200 and headers["x-iso-triangles"] == triangles, (st, headers.get("x-iso-triangles"))
        base, base_vm = mapped_bytes(pid), vm_bytes(pid)
        # The second cap is met after extraction, by the encoder or by the edge census that
        # runs beside it on another thread: whichever asks last for the memory left.
        for spare_mib, normals, steps in ((48, "tricubic", ["out of memory extracting the surface"]),
                                          (700, "none", ["draco encode: out of memory",
                                                         "out of memory counting edges"])):
            resource.prlimit(pid, resource.RLIMIT_AS, (base_vm + (spare_mib << 20), resource.RLIM_INFINITY))
            target = f"/v1/volumes/noise/mesh?level=127.5&tolerance=0&normals={normals}".encode()
            st, h, got = get(s.port, target)
            answer = json.loads(got)
            assert st == 503 and h.get("content-type") == "application/problem+json", (st, got[:300])
            assert answer in [problem(503, "Service Unavailable", "unavailable",
                                      f"noise: {step}; a larger tolerance gives a smaller mesh",
                                      "/v1/volumes/noise/mesh") for step in steps], (spare_mib, answer)
            assert h.get("retry-after") == "1", h
            st, headers, _ = get(s.port, small.encode())
            assert st == 200 and headers["x-iso-triangles"] == triangles, (spare_mib, st, headers.get("x-iso-triangles"))
            st, _, body = get(s.port, b"/healthz")
            assert st == 200 and json.loads(body)["status"] == "ready", (spare_mib, st, body)
        # The memory of the failed requests went back: the address space is what it was.
        # Threads the server starts meanwhile (a stack each) and the malloc arenas they may
        # get (64 MiB reserved each), which depend on how threads overlap under load, are
        # not the requests' memory; every other mapping must be back to what it was.
        after = mapped_bytes(pid)
        assert after["other"] <= base["other"] + (8 << 20), (after, base)
        assert s.metric('isoserve_http_requests_total{route="mesh",status="503"}') == 2
    finally:
        rc = s.stop()
    assert rc == 0, (rc, s.log()[-600:])


# ---------------------------------------------------------------- the hierarchy cache's faults

def cache_write_fails(tmp):
    """A file size limit (RLIMIT_FSIZE) makes every hierarchy write fail with EFBIG, as a
    full disk fails with ENOSPC: the server logs it, counts it, serves from memory, and
    leaves no file behind (not even a partial temporary one)."""
    cache = os.path.join(tmp, "full-cache")
    os.mkdir(cache)
    cat = os.path.join(tmp, "fault.json")
    json.dump({"volumes": [{"id": "ml", "path": "field:ml:64", "levels": [0.5]}]}, open(cat, "w"))

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
    saved = subprocess.Popen
    subprocess.Popen = lambda *a, **k: saved(*a, preexec_fn=limit, **k)  # only this server
    try:
        s = test_http.Server(["--catalog", cat, "--cache-dir", cache])
    finally:
        subprocess.Popen = saved
    try:
        assert s.wait_log(r"ml: hierarchy not cached: .*File too large; serving it from memory"), s.log()[-500:]
        assert s.get("/v1/volumes/ml/mesh?level=0.5&tolerance=0.01").status == 200
        assert s.metric("isoserve_hierarchies_unsaved") == 1
    finally:
        rc = s.stop()
    assert rc == 0, rc
    assert os.listdir(cache) == [], os.listdir(cache)


def server_under(tracer, timeout=10):
    """The pid of the server strace started: its child running BIN (strace forks probes of
    its own first)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        with open(f"/proc/{tracer}/task/{tracer}/children") as f:
            kids = f.read().split()
        for kid in kids:
            try:
                with open(f"/proc/{kid}/cmdline", "rb") as f:
                    if f.read().split(b"\0")[:2] == [BIN.encode(), b"serve"]:
                        return int(kid)
            except FileNotFoundError:
                pass
        time.sleep(0.01)
    raise AssertionError(f"strace ({tracer}) started no server")


def gone(pid, timeout=10):
    """Waits until pid has exited (a zombie, or reaped)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X"):
                    return
        except FileNotFoundError:
            return
        time.sleep(0.01)
    raise AssertionError(f"process {pid} still runs {timeout} s after SIGKILL")


def kill_in_fsync(cat, cache):
    """A kill -9 certain to land between a hierarchy's write and its rename: the server runs
    under strace, which holds every fsync for 60 s; once v0's temporary file is there (written,
    in fsync), a second server is started on the same directory, as a replica sharing it
    would be, and must keep the file (its writer is alive); then the first server is killed
    by its PID. Returns the file's name."""
    path = os.path.join(cache, "v0.isotree")
    if os.path.exists(path):
        os.unlink(path)  # v0 is built and written again
    tracer = subprocess.Popen(["strace", "-f", "--seccomp-bpf", "-qq", "-o", "/dev/null", "-e", "trace=fsync",
                               "-e", "inject=fsync:delay_enter=60000000",
                               BIN, "serve", "--catalog", cat, "--cache-dir", cache, "--listen", "127.0.0.1:0"],
                              stderr=subprocess.DEVNULL)
    server = None
    try:
        server = server_under(tracer.pid)
        deadline = time.time() + 60
        held = []
        while not held and time.time() < deadline:
            held = [n for n in os.listdir(cache) if n.startswith("v0.isotree.tmp.")]
            time.sleep(0.01)
        assert held, "no temporary file of v0 within 60 s"
        other = test_http.Server(["--catalog", cat, "--cache-dir", cache])
        try:
            kept = rf"^isoserve: {re.escape(cache)}/{re.escape(held[0])}: kept: changed [0-9] s ago, its writer may still be at work \(stale after 60 s\)$"
            assert re.search(kept, other.log(), re.M), other.log()[-800:]
            assert held[0] in os.listdir(cache)
        finally:
            assert other.stop() == 0
        os.kill(server, signal.SIGKILL)
        gone(server)
        return held[0]
    finally:
        # strace sleeps out its injected delay before it notices the kill: stopped too.
        if server and os.path.exists(f"/proc/{server}"):
            os.kill(server, signal.SIGKILL)
        tracer.kill()
        tracer.wait()


def kill_during_build(tmp):
    """kill -9 while hierarchies are being built and written: whatever is left in the cache
    dir under a real name loads (or is refused by its checksums and rebuilt); temporary
    files are never taken. Repeated at several moments, then once inside a write for certain
    (kill_in_fsync). The next start keeps the fresh temporary files (a replica sharing the
    directory could be writing them) and says so; a start two minutes later (their times
    moved back) removes each one, logs it, and leaves every other file alone."""
    cache = os.path.join(tmp, "kill-cache")
    os.mkdir(cache)
    cat = os.path.join(tmp, "kill.json")
    json.dump({"volumes": [{"id": f"v{i}", "path": f"field:ml:{96 + 8 * i}", "levels": [0.5]} for i in range(4)]},
              open(cat, "w"))
    for delay in (0.2, 0.6, 1.0):
        p = subprocess.Popen([BIN, "serve", "--catalog", cat, "--cache-dir", cache, "--listen", "127.0.0.1:0"],
                             stderr=subprocess.DEVNULL)
        time.sleep(delay)
        p.send_signal(signal.SIGKILL)
        p.wait()
    if not shutil.which("strace"):
        raise Skip("strace is missing (scripts/setup.sh installs it): no kill is certain to land inside a write")
    held = kill_in_fsync(cat, cache)
    names = os.listdir(cache)
    left = sorted(n for n in names if ".isotree.tmp." in n)
    assert held in left, (held, names)
    s = test_http.Server(["--catalog", cat, "--cache-dir", cache])
    try:
        for i in range(4):
            r = s.get(f"/v1/volumes/v{i}/mesh?level=0.5&tolerance=0.05&normals=none")
            assert r.status == 200, (i, r.status)
        assert s.metric("isoserve_volumes_loaded") == 4
        for n in left:
            assert f"isoserve: {cache}/{n}: kept: changed " in s.log(), (n, s.log()[-800:])
    finally:
        assert s.stop() == 0
    done = sorted(n for n in os.listdir(cache) if n.endswith(".isotree"))
    assert done == [f"v{i}.isotree" for i in range(4)], (names, os.listdir(cache))
    assert sorted(n for n in os.listdir(cache) if ".isotree.tmp." in n) == left

    # Two minutes on. Beside the leftovers, files that look alike but are not a temporary
    # file of a catalog id: another id, five or non-alphanumeric letters, another suffix,
    # a symbolic link.
    sizes = {n: os.path.getsize(os.path.join(cache, n)) for n in left}
    decoys = ["v9.isotree.tmp.Ab3dE5", "v1.isotree.tmp.Ab3dE", "v1.isotree.tmp.Ab-dE5", "v1.isotree.part"]
    for n in decoys:
        with open(os.path.join(cache, n), "wb") as f:
            f.write(b"x" * 100)
    os.symlink("v2.isotree", os.path.join(cache, "v2.isotree.tmp.Lnk123"))
    past = time.time() - 120
    for n in left + decoys + ["v2.isotree.tmp.Lnk123"]:
        os.utime(os.path.join(cache, n), (past, past), follow_symlinks=False)
    s = test_http.Server(["--catalog", cat, "--cache-dir", cache])
    try:
        removed = re.findall(r"^isoserve: (.*): removed, a stale temporary file \((\d+) bytes, unchanged for (\d+) s: "
                             r"its writer is gone\)$", s.log(), re.M)
        assert sorted((p, int(b)) for p, b, _ in removed) == sorted((f"{cache}/{n}", sizes[n]) for n in left), removed
        assert all(120 <= int(idle) <= 150 for _, _, idle in removed), removed
        assert s.metric("isoserve_volumes_loaded") == 4
    finally:
        assert s.stop() == 0
    kept = sorted(n for n in os.listdir(cache) if not n.endswith(".isochain"))  # the background's chains aside
    assert kept == sorted(done + decoys + ["v2.isotree.tmp.Lnk123"]), os.listdir(cache)
    print(f"INFO {LABEL}.kill_during_build: {len(left)} temporary files left by 4 kills, removed two minutes later",
          flush=True)


def truncated_file_rebuilt(tmp):
    cache = os.path.join(tmp, "trunc-cache")
    os.mkdir(cache)
    cat = os.path.join(tmp, "trunc.json")
    json.dump({"volumes": [{"id": "ml", "path": "field:ml:48", "levels": [0.5]}]}, open(cat, "w"))
    s = test_http.Server(["--catalog", cat, "--cache-dir", cache])
    assert s.stop() == 0
    path = os.path.join(cache, "ml.isotree")
    size = os.path.getsize(path)
    with open(path, "r+b") as f:
        f.truncate(size - 7)
    s = test_http.Server(["--catalog", cat, "--cache-dir", cache])
    try:
        bricks = (-(-(48 - 1) // 8)) ** 3  # 17 one-byte level codes per brick of 8^3 cells after the nodes
        nodes = (size - 64 - 17 * bricks) // 12
        want = (f"isoserve: ml: {path}: {size - 7} bytes do not hold the {nodes} nodes the header announces "
                f"and {17 * bricks} level errors; rebuilding")
        assert want in s.log(), s.log()
        assert s.get("/v1/volumes/ml/mesh?level=0.5").status == 200
    finally:
        assert s.stop() == 0
    assert os.path.getsize(path) == size


def main():
    RESULTS.report("binary", os.access(BIN, os.X_OK), f"{BIN} missing (run make)")
    if RESULTS.failures:
        return 1
    tmp = tempfile.mkdtemp(prefix="isoserve-hostile-")
    try:
        open(os.path.join(tmp, "index.html"), "w").write("<!doctype html><title>t</title>")
        catalog = os.path.join(tmp, "volumes.json")
        json.dump({"volumes": [{"id": "sphere", "path": "field:sphere:24", "levels": [4]},
                               {"id": "ml", "path": "field:ml:64", "levels": [0.5]}]}, open(catalog, "w"))
        RESULTS.check("server", lambda: open_server_tests(tmp, catalog))
        RESULTS.check("token_server", lambda: token_tests(tmp, catalog))
        RESULTS.check("one_request_out_of_memory", lambda: out_of_memory(tmp))
        RESULTS.check("cache_write_fails", lambda: cache_write_fails(tmp))
        RESULTS.check("kill_during_build", lambda: kill_during_build(tmp))
        RESULTS.check("truncated_file_rebuilt", lambda: truncated_file_rebuilt(tmp))
    finally:
        subprocess.run(["rm", "-rf", tmp])
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
