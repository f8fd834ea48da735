#!/usr/bin/env bash
# The command line explains itself: `isoserve --help` lists every command; each command
# answers -h, --help and `isoserve help CMD` with its own usage on stdout (exit 0); and the
# options a usage lists are exactly those its parser takes. The option names come from the
# code: every "--name" (and "-o") string literal in server/*.c. Each command is run with
# each of those of its own source file (the one that defines srv_CMD_command) and cli.c,
# followed by --help: a listed option (given a value when it takes one) must not be refused
# as unknown, any other must be ("unknown option", exit 1); and every such literal of any
# file must be listed by some command. Prints PASS/FAIL lines.
set -uo pipefail
cd "$(dirname "$0")/../.."
bin=${ISOSERVE_BIN:-build/isoserve}
exec /usr/bin/python3 - "$bin" "${ISO_SAN_SUFFIX:-}" <<'PY'
import glob, re, subprocess, sys
from concurrent.futures import ThreadPoolExecutor

BIN, SUFFIX = sys.argv[1], sys.argv[2]
failures = 0


def report(name, ok, why=""):
    global failures
    failures += not ok
    print(f"PASS cli{SUFFIX}.{name}" if ok else f"FAIL cli{SUFFIX}.{name}: {why}")


def run(*args):
    p = subprocess.run([BIN, *args], capture_output=True, text=True, timeout=60)
    return p.returncode, p.stdout, p.stderr


def listed_options(text):
    """{name: value placeholder or None} of a usage's option lines ("  --level L   ...")."""
    options = {}
    for line in text.split("options:\n", 1)[-1].splitlines():
        m = re.match(r"  (-[-a-z]+)(?: ([^ ]+))?(?:  +\S|$)", line)
        if m and m.group(1) not in ("-h,",):
            options[m.group(1)] = m.group(2)
    return options


rc, top, err = run("--help")
commands = re.findall(r"^  isoserve (\w+) ", top, re.M)
report("usage_lists_commands", rc == 0 and commands == ["info", "build", "extract", "serve", "segments", "bench"],
       f"status {rc}, commands {commands}: {err}")

sources = {path: open(path).read() for path in glob.glob("server/*.c")}
found = {path: set(re.findall(r'"(--[a-z][a-z-]*|-o)"', text)) - {"--help"} for path, text in sources.items()}
literals = set().union(*found.values())

every_listed = set()
for cmd in commands:
    rc, usage, err = run(cmd, "--help")
    rc_h, usage_h, _ = run(cmd, "-h")
    rc_help, usage_help, _ = run("help", cmd)
    report(f"{cmd}_help", rc == 0 and usage.startswith(f"usage: isoserve {cmd} ") and not err and
           (rc_h, usage_h) == (0, usage) and (rc_help, usage_help) == (0, usage),
           f"status {rc}/{rc_h}/{rc_help}, stdout {usage[:80]!r}, stderr {err[:200]!r}")
    options = listed_options(usage)
    every_listed |= set(options)
    wrong = []
    own = [path for path, text in sources.items() if re.search(rf"\bsrv_{cmd}_command = {{", text)]
    probe = set(options).union(found["server/cli.c"], *(found[path] for path in own))
    names = sorted(probe)
    with ThreadPoolExecutor(2) as pool:  # each run is mostly process start-up (ASan's too)
        answers = list(pool.map(lambda n: run(cmd, n, *(["1"] if options.get(n) else []), "--help"), names))
    for name, (rc, out, err) in zip(names, answers):
        unknown = f"unknown option '{name}'" in err
        if name in options and (unknown or (rc == 0 and not out.startswith("usage:"))):
            wrong.append(f"{name} listed but refused ({err.strip()[:120]})")
        if name not in options and not (unknown and rc == 1):
            wrong.append(f"{name} parsed but not listed (status {rc})")
    report(f"{cmd}_usage_matches_parser", len(own) == 1 and options and not wrong,
           "; ".join(wrong) or f"no options listed, or not one file defines srv_{cmd}_command: {own}")

report("every_option_listed", literals <= every_listed, f"parsed, listed by no command: {sorted(literals - every_listed)}")
sys.exit(1 if failures else 0)
PY
