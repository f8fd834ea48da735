"""Lint of docker/ without a Docker engine: what `docker build` and `docker compose up`
would trip on first, checked from the files.

- compose.yaml is valid YAML (Debian's python3-yaml), its build contexts, Dockerfiles and
  targets exist, its bind-mounted paths exist;
- every COPY source of the Dockerfile exists in the build context, every `--from` names an
  earlier stage, every `make X` it runs is a Makefile target (`make -n X` succeeds);
- the server stage runs as a non-root user, exposes its port and checks /healthz;
- the image gets no test tool (no npm in the build, .dockerignore admits only runtime
  packages);
- the shard ring's three copies agree: ISOSERVE_SHARD_PEERS in compose, the `server` lines
  of both upstream blocks in nginx.conf (same names, same order, weight 1), and the
  replicas' ISOSERVE_SHARD K/N cover 0..N-1 once each;
- Debian's podman-compose substitutes every variable of compose.yaml (an empty default
  it would leave as it is), and every service has a compose healthcheck.
Prints PASS/FAIL/SKIP lines; exit status 1 on failure."""

import os
import re
import shlex
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from results import Results, Skip  # noqa: E402 - found through the path just set

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
DOCKER = os.path.join(ROOT, "docker")
RESULTS = Results("docker-lint")


def default_of(value):
    """Compose's ${VAR:-default} (or ${VAR}) reduced to what it is when VAR is unset."""
    return re.sub(r"\$\{[A-Za-z_][A-Za-z0-9_]*(?::?-([^}]*))?\}", lambda m: m.group(1) or "", value)


def dockerfile_instructions(path):
    """(stage, instruction, arguments) per instruction, continuation lines joined. The ARGs
    before the first FROM (stage None) are substituted into the FROM lines with their
    defaults, as a build without --build-arg sees them."""
    text = open(path).read().replace("\\\n", " ")
    stage, out, defaults = None, [], {}
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        word, _, rest = line.partition(" ")
        word = word.upper()
        if word == "ARG" and stage is None and "=" in rest:
            name, _, value = rest.strip().partition("=")
            defaults[name] = value
        if word == "FROM":
            rest = re.sub(r"\$\{(\w+)\}", lambda m: defaults.get(m.group(1), m.group(0)), rest)
            m = re.search(r"\bAS\s+(\S+)", rest, re.I)
            stage = m.group(1) if m else None
        out.append((stage, word, rest.strip()))
    return out


def load_compose():
    try:
        import yaml
    except ImportError:
        raise Skip("python3-yaml is not installed (scripts/setup.sh installs it)")
    with open(os.path.join(DOCKER, "compose.yaml")) as f:
        compose = yaml.safe_load(f)
    assert isinstance(compose, dict) and isinstance(compose.get("services"), dict), "no services"
    return compose


def compose_paths():
    compose = load_compose()
    stages = {}
    for name, service in compose["services"].items():
        build = service.get("build")
        if build:
            context = os.path.normpath(os.path.join(DOCKER, build["context"]))
            dockerfile = os.path.join(context, build.get("dockerfile", "Dockerfile"))
            assert os.path.isdir(context), (name, context)
            assert os.path.isfile(dockerfile), (name, dockerfile)
            if dockerfile not in stages:
                stages[dockerfile] = {s for s, w, _ in dockerfile_instructions(dockerfile) if w == "FROM"}
            assert build.get("target") in stages[dockerfile] | {None}, (name, build.get("target"))
        for volume in service.get("volumes", []):
            source = default_of(volume).split(":")[0] if isinstance(volume, str) else volume["source"]
            if source.startswith((".", "/")):
                assert os.path.exists(os.path.join(DOCKER, source)), (name, volume, "missing")
            else:
                assert source in (compose.get("volumes") or {}), (name, volume, "undeclared volume")


def dockerfile_sources():
    path = os.path.join(DOCKER, "Dockerfile")
    stages_so_far, makes = set(), []  # makes: the RUN lines
    for stage, word, rest in dockerfile_instructions(path):
        if word == "FROM":
            stages_so_far.add(stage)
        elif word == "COPY":
            args = shlex.split(rest)
            source_from = [a for a in args if a.startswith("--from=")]
            paths = [a for a in args if not a.startswith("--")][:-1]
            if source_from:
                assert source_from[0][7:] in stages_so_far, ("COPY", rest, "no such earlier stage")
                continue
            for p in paths:
                assert os.path.exists(os.path.join(ROOT, p)), ("COPY", p, "not in the repository")
        elif word == "RUN":
            makes.append(rest)
    targets = []
    for run in makes:  # the words after `make` up to the end of its command, options aside
        words = run.split()
        for i, w in enumerate(words):
            if w != "make":
                continue
            for t in words[i + 1:]:
                if t in ("&&", "||", ";", "|"):
                    break
                if not t.startswith("-") and "=" not in t and "$" not in t:
                    targets.append(t)
    assert targets, "the Dockerfile runs no make target"
    for t in targets:
        p = subprocess.run(["make", "-n", t], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert p.returncode == 0, (t, p.stderr.strip()[-300:])
    print(f"INFO docker-lint.make_targets: {' '.join(targets)}", flush=True)


def server_stage():
    steps = dockerfile_instructions(os.path.join(DOCKER, "Dockerfile"))
    last = steps[-1][0]
    mine = [(w, r) for s, w, r in steps if s == last]
    assert re.match(r"debian:bookworm-slim\b", next(r for w, r in mine if w == "FROM")), "not bookworm-slim"
    users = [r for w, r in mine if w == "USER"]
    assert users and users[-1] not in ("root", "0"), users
    assert any(w == "EXPOSE" for w, _ in mine), "no EXPOSE"
    assert any(w == "HEALTHCHECK" and "/healthz" in r for w, r in mine), "no HEALTHCHECK on /healthz"
    assert any(w == "VOLUME" for w, _ in mine), "no VOLUME"


# What debian:bookworm-slim already holds among the libraries isoserve links.
SLIM_BASE = {"libc6", "libgcc-s1", "libstdc++6", "zlib1g"}


def apt_packages(stage_steps):
    """Package names of a stage's `apt-get install` commands."""
    names = set()
    for w, r in stage_steps:
        if w != "RUN":
            continue
        for cmd in re.findall(r"apt-get install ([^&|;]*)", r):
            names.update(t for t in cmd.split() if not t.startswith("-") and "=" not in t)
    return names


def package_of(path):
    owner = subprocess.run(["dpkg", "-S", path], capture_output=True, text=True)
    if owner.returncode != 0:
        owner = subprocess.run(["dpkg", "-S", os.path.realpath(path)], capture_output=True, text=True)
    return owner.stdout.split(":")[0] if owner.returncode == 0 else None


def dev_package_of(link):
    """The package owning an unversioned libX.so link itself (not what it points to)."""
    owner = subprocess.run(["dpkg", "-S", link], capture_output=True, text=True)
    return owner.stdout.split(":")[0] if owner.returncode == 0 else None


def runtime_libraries():
    """Every library the built daemon links directly (its NEEDED entries) comes from a
    package the server stage installs or the slim base has, and its development package
    (the owner of the unversioned libX.so link) is installed by the build stage: found
    with readelf, ldd and dpkg -S on this Debian 12. apt brings what those need."""
    binary = os.environ.get("ISOSERVE_BIN", os.path.join(ROOT, "build", "isoserve"))
    if not os.path.exists(binary):
        raise Skip(f"{binary} is not built")
    steps = dockerfile_instructions(os.path.join(DOCKER, "Dockerfile"))
    stages = []
    for stage, _, _ in steps:
        if stage is not None and stage not in stages:
            stages.append(stage)
    build = apt_packages([(w, r) for st, w, r in steps if st == stages[0]])
    server = apt_packages([(w, r) for st, w, r in steps if st == stages[-1]])
    dynamic = subprocess.run(["readelf", "-d", binary], capture_output=True, text=True, check=True).stdout
    needed = set(re.findall(r"\(NEEDED\)\s+Shared library: \[(\S+)\]", dynamic))
    ldd = dict(re.findall(r"^\s*(\S+) => (/\S+)", subprocess.run(["ldd", binary], capture_output=True,
                                                                   text=True, check=True).stdout, re.M))
    missing_runtime, missing_dev = [], []
    for soname in sorted(needed):
        package = package_of(ldd.get(soname, ""))
        if package is None or package in SLIM_BASE or "san" in soname:
            continue  # libc and friends, or a sanitizer runtime of an ASan build
        if package not in server:
            missing_runtime.append(f"{package} ({soname})")
        link = soname.split(".so")[0] + ".so"
        dev = next(filter(None, (dev_package_of(os.path.join(d, link)) for d in
                                 (os.path.dirname(ldd[soname]), "/usr/lib/x86_64-linux-gnu", "/usr/lib"))), None)
        if dev and dev not in build:
            missing_dev.append(f"{dev} ({soname})")
    assert not missing_runtime, f"the server stage lacks {missing_runtime}"
    assert not missing_dev, f"the build stage lacks {missing_dev}"


def ring_agrees():
    compose = load_compose()
    conf = open(os.path.join(DOCKER, "nginx.conf")).read()
    blocks = re.findall(r"upstream\s+(\S+)\s*\{(.*?)\}", conf, re.S)
    assert blocks, "nginx.conf has no upstream block"
    lists = {name: re.findall(r"^\s*server\s+(\S+)", body, re.M) for name, body in blocks}
    # isoserve's ring gives every peer weight 1 (160 points), and a backup is not on it.
    odd = re.findall(r"^\s*server\s.*\b(weight=\d+|backup)\b", conf, re.M)
    assert not odd, f"nginx.conf upstream servers with {odd}: --shard-peers assumes weight 1, no backup"
    replicas = {n: s for n, s in compose["services"].items() if "ISOSERVE_SHARD" in (s.get("environment") or {})}
    peers = {tuple(s["environment"]["ISOSERVE_SHARD_PEERS"].split(",")) for s in replicas.values()}
    assert len(peers) == 1, f"replicas disagree on ISOSERVE_SHARD_PEERS: {peers}"
    peers = list(peers.pop())
    for name, servers in lists.items():
        assert servers == peers, f"upstream {name} lists {servers}, compose's peers are {peers}"
    shards = sorted(s["environment"]["ISOSERVE_SHARD"] for s in replicas.values())
    n = len(peers)
    assert shards == sorted(f"{k}/{n}" for k in range(n)), shards
    for name, s in replicas.items():
        k = int(s["environment"]["ISOSERVE_SHARD"].split("/")[0])
        assert peers[k].split(":")[0] in (name, s.get("hostname")), (name, "is not", peers[k])


def compose_substitutions():
    """Every ${...} of compose.yaml substituted as Debian 12's podman-compose does it (its
    own rec_subs, with none of the variables set): nothing is left unsubstituted, and the
    catalog and volumes variables have no value (compose passes them from its caller's
    environment when set there) or a blank one, which isoserve takes as unset. Without
    podman-compose installed, what it is known to leave: an empty default "${X:-}"."""
    text = "\n".join(line.split("#")[0] for line in open(os.path.join(DOCKER, "compose.yaml")))
    empty = re.findall(r"\$\{[A-Za-z_][A-Za-z0-9_]*:?-\}", text)
    assert not empty, f"empty compose defaults {empty}: podman-compose leaves them unsubstituted"
    try:
        import podman_compose
    except ImportError:
        raise Skip("Debian's podman-compose is not installed")
    compose = load_compose()
    env = {k: v for k, v in os.environ.items() if not k.startswith("ISOSERVE_")}
    out = podman_compose.rec_subs(compose, env)
    left = [(name, k, v) for name, svc in out["services"].items() for k, v in (svc.get("environment") or {}).items()
            if "${" in str(v)]
    assert not left, left
    for name, svc in out["services"].items():
        e = svc.get("environment") or {}
        for k in ("ISOSERVE_CATALOG", "ISOSERVE_VOLUMES"):
            assert k not in e or e[k] is None or not str(e[k]).strip(), (name, k, e.get(k))
    healthy = [n for n, svc in out["services"].items() if svc.get("healthcheck")]
    assert sorted(healthy) == sorted(out["services"]), f"services without a healthcheck: {healthy}"


def no_test_tools_in_image():
    """The build runs no npm; of web/node_modules, .dockerignore lets through only the
    runtime dependencies of web/package.json, and every test tool is a devDependency."""
    import json
    package = json.load(open(os.path.join(ROOT, "web", "package.json")))
    runtime, dev = set(package.get("dependencies", {})), set(package.get("devDependencies", {}))
    assert {"playwright-core", "draco3d"} <= dev, f"test tools missing from devDependencies: {dev}"
    runs = [r for _, w, r in dockerfile_instructions(os.path.join(DOCKER, "Dockerfile")) if w == "RUN"]
    assert not [r for r in runs if re.search(r"\bnpm\b|node-deps", r)], "the image build runs npm"
    ignore = [line.strip() for line in open(os.path.join(ROOT, ".dockerignore")) if line.strip()
              and not line.startswith("#")]
    assert "web/node_modules" in ignore, ".dockerignore lets every npm package in"
    admitted = {line[len("!web/node_modules/"):] for line in ignore if line.startswith("!web/node_modules/")}
    admitted.discard(".package-lock.json")
    assert admitted <= runtime, f".dockerignore lets in {admitted - runtime}, not runtime dependencies"


def main():
    RESULTS.check("compose_yaml_paths_and_targets", compose_paths)
    RESULTS.check("dockerfile_copy_sources_and_make_targets", dockerfile_sources)
    RESULTS.check("server_image_nonroot_healthcheck", server_stage)
    RESULTS.check("server_image_has_every_shared_library", runtime_libraries)
    RESULTS.check("shard_peers_match_nginx_upstreams", ring_agrees)
    RESULTS.check("compose_substituted_by_podman_compose", compose_substitutions)
    RESULTS.check("image_installs_no_test_tools", no_test_tools_in_image)
    return 1 if RESULTS.failures else 0


if __name__ == "__main__":
    sys.exit(main())
